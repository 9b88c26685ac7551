"""``tollcli integrity``: a receiver log → the epoch table with RAIM columns."""

from __future__ import annotations

import json
from collections import Counter
from typing import Annotated, Optional

import pandas as pd
import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note, progress
from tollcli.cli.settings_file import Config
from tollcli.errors import PartialError, UsageError
from tollcli.gnss.sigma_models import SIGMA_MODELS, NominalModel
from tollcli.integrity.environment import ENVIRONMENTS
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.sources import LEVEL_CHOICES, LEVELS
from tollcli.io.log_run import LogRun
from tollcli.io.writers import TableWriter, format_for
from tollcli.job.log_integrity import iter_integrity, tally_verdicts, with_epoch_checks
from tollcli.readers.navigation import NAVIGATION_KINDS
from tollcli.readers.nmea import ReadStats
from tollcli.readers.nmea.reader import check_partial, check_usable


def integrity(
    log: opt.LogArg,
    output: opt.Output = "-",
    out_fmt: opt.TableFormat = None,
    input_format: opt.InputFormat = "auto",
    nav: opt.Nav = None,
    integrity_sources: opt.IntegritySources = "auto",
    raim: opt.RaimMode = "ss",
    environment: opt.Environment = "auto",
    positioning: opt.Positioning = "auto",
    p_sat: opt.PSat = 1e-5,
    p_const: opt.PConst = 1e-8,
    hal: opt.Hal = 50.0,
    p_md: opt.PMd = 5e-5,
    p_fa: opt.PFa = 5e-3,
    fde: opt.Fde = False,
    sigma_model: opt.SigmaModel = "nominal",
    sigma: opt.Sigma = 5.0,
    iono: opt.Iono = "single",
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
    max_bad: opt.MaxBad = None,
    checks: Annotated[bool, typer.Option("--checks", help="Add the speed check, the Kalman HIT and (with --roads) map matching and its fuzzy integrity; reads the whole log first.")] = False,
    roads: Annotated[Optional[str], typer.Option("--roads", help="Road network (GeoJSON LineStrings) to match onto; implies --checks.")] = None,
    config: Config = None,
) -> None:
    """Check every epoch with every integrity source the log has and write the epoch table with its verdict.

    The RAIM (--raim): ss, the default, compares the position with the positions
    without each satellite (solution separation: several faults at once, HPL
    over every fault mode and the noise, separation_ratio > 1 a detected fault);
    etc and classic are paper 001's single-fault tests. The error model's
    environment (--environment auto): an epoch whose residuals of the last 30 s
    exceed the model 1.5-fold is urban and gets the C/N0-weighted urban σ
    (columns environment, variance_factor). raim_lat_deg/raim_lon_deg is the
    position the RAIM vouches for (its own weighted solution, after any exclusion).

    Sources: the RAIM on GRS residuals or pseudoranges, the receiver's own
    RAIM (GBS) and its error ellipse (GST); the strictest verdict wins
    (raim_status), the deciding source is integrity_source, each source's own
    verdict is kept (residual_status, gbs_status, gst_status, hpl_gbs_m,
    hpl_gst_m), and gst_rms_note says where a GST RMS field was ignored as no
    range RMS. Adds raim_mode, n_used, dof, slope_max_m, test_stat, test_stat_source,
    threshold, lambda_det, hpl_m, hal_m, p_fa, p_md, raim_status, excluded_sv,
    fde_shift_e_m, fde_shift_n_m and raim_lat_deg/raim_lon_deg. Statuses: valid,
    fault_detected (t > Th at P_FA ≤ --p-fa: a credible alarm), probable_false_alarm
    (ETC: t > Th, but this epoch's P_FA is above --p-fa — not trusted, no evidence
    of a fault), excluded_valid, unavailable, unmonitored (no residuals in the
    log), insufficient (fewer than unknowns + 1 measurements). docs/integrity.md
    measures every setting against the truth of real drives.
    """
    out_fmt, fmt = opt.split_format(out_fmt, input_format)
    if sigma_model not in SIGMA_MODELS:
        raise UsageError(f"--sigma-model {sigma_model}: use one of {', '.join(SIGMA_MODELS)}")
    if iono not in ("single", "sbas", "iono-free"):
        raise UsageError(f"--iono {iono}: use single, sbas or iono-free")
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the table a file with -o")
    try:
        if integrity_sources not in LEVEL_CHOICES:
            raise ValueError(f"--integrity-sources {integrity_sources}: use one of {', '.join(LEVEL_CHOICES)}")
        params = RaimParams(mode=raim, hal_m=hal, p_md=p_md, p_fa=p_fa, fde=fde, p_sat=p_sat, p_const=p_const,
                            sources=LEVELS.get(integrity_sources))
        if environment not in ENVIRONMENTS:
            raise ValueError(f"--environment {environment}: use one of {', '.join(ENVIRONMENTS)}")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    nominal = NominalModel(iono=iono)
    nav = opt.nav_files(nav)
    run = LogRun(log, fmt)  # the log opened once (io.log_run)
    kind = run.kind
    with run:
        day = date.date() if date else None
        counts: Counter[str] = Counter()
        writer = TableWriter(output, format_for(output, fmt=out_fmt))
        stats = ReadStats()
        with writer:
            if checks or roads:
                tables = [c.table for c in iter_integrity(run, kind, params, sigma_model, sigma, nominal, strict, stats, nav=nav,
                                                          date=day, environment=environment, positioning=positioning)]
                if kind in NAVIGATION_KINDS:
                    check_usable(stats)  # a log without one epoch: the data error, before any check runs
                if kind not in NAVIGATION_KINDS and tables:  # a pseudorange log's malformed lines (each chunk says them)
                    counts["skipped", "lines"] += int(tables[0].attrs.get("skipped_lines", 0))
                table = with_epoch_checks(pd.concat(tables, ignore_index=True), roads)
                used = table["positioning"].iat[0] if "positioning" in table and len(table) else "snapshot"
                note_why = tables[0].attrs.get("positioning_note") if tables else None
                tally_verdicts(table, counts)
                writer.write(table)
            elif kind in NAVIGATION_KINDS:
                _stream_navigation_log(run, writer, params, sigma_model, sigma, nominal, strict, quiet, counts, stats, day, environment, kind)
            else:  # chunk by chunk: a long libRSF or GSDC log is placed segment by segment, its table written as it comes
                used, note_why = "snapshot", None
                for i, chunk in enumerate(iter_integrity(run, kind, params, sigma_model, sigma, nominal, strict, stats, nav=nav,
                                                         environment=environment, positioning=positioning)):  # fmt: skip
                    table = chunk.table
                    if i == 0:
                        used = table["positioning"].iat[0] if "positioning" in table and len(table) else table.attrs.get("positioning_used", "snapshot")
                        note_why = table.attrs.get("positioning_note")
                        counts["skipped", "lines"] += int(table.attrs.get("skipped_lines", 0))
                    tally_verdicts(table, counts)
                    writer.write(table)
                if note_why:
                    note_why = note_why.replace(run.replay_path(), run.name)
            writer.commit()
        stats.source, stats.first_problem = run.named(stats.source), run.named(stats.first_problem)  # (not the log's copy)
    # the malformed lines the reader passed over: a navigation log's reader's, or a pseudorange log's (its table says),
    # or the receiver's own solutions' read instead of a u-blox log's pseudoranges (no orbits)
    counts["skipped", "lines"] += stats.skipped
    statuses = {k[1]: n for k, n in sorted(counts.items()) if k[0] == "status"}
    sources = {k[1]: n for k, n in sorted(counts.items()) if k[0] == "source"}
    ignored = {k[1]: n for k, n in sorted(counts.items()) if k[0] == "note" and k[1]}
    summary = {"statuses": statuses, "epochs": sum(statuses.values()), "format": kind,
               "integrity_sources": sources, "integrity_sources_setting": integrity_sources, "gst_rms_ignored": ignored,
               "raim": raim, "hal_m": hal, "p_md": p_md, "p_fa": p_fa if raim != "etc" else None,
               "fde": fde, "sigma_model": sigma_model, "environment_setting": environment,
               "environments": {k[1] or "unknown": n for k, n in sorted(counts.items()) if k[0] == "environment"},
               "skipped_lines": counts["skipped", "lines"]}  # fmt: skip
    if run.decoded_by:  # a binary protocol, read as gpsd reports it
        summary.update(format="gpsd-binary", decoded_by=run.decoded_by)
    if kind == "gpsd-json" and not set(sources) & {"grs", "pseudorange"}:  # what gpsd's JSON lost of the receiver's evidence
        from tollcli.job.receiver_notes import GPSD_DROPPED

        summary["receiver_notes"] = {"gpsd_json": GPSD_DROPPED}
    if kind not in NAVIGATION_KINDS:
        summary.update(positioning=positioning, positioning_used=used)
        if note_why:
            summary["positioning_note"] = note_why
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True))
    else:
        text = f"{log}: {summary['epochs']} epochs: " + ", ".join(f"{n} {s}" for s, n in statuses.items())
        text += "; decided by " + ", ".join(f"{s} {n}" for s, n in sources.items())
        if counts["skipped", "lines"]:
            text += f"; skipped {counts['skipped', 'lines']} malformed lines (--strict: an error)"
        if sources.get("model"):
            text += ("; model level: the satellites' geometry and an error model only, no fault detection ("
                     + {"auto": "no residuals: the urban σ but for corrected fixes; --environment open declares open country",
                        "open": "environment open, as declared: the nominal σ",
                        "urban": "environment urban, as declared: the urban σ"}.get(environment, environment) + ")")  # fmt: skip
        if summary["environments"]:
            text += "; environment " + ", ".join(f"{n} {e}" for e, n in summary["environments"].items())
        if ignored:
            rms = {k: n for k, n in ignored.items() if k != "contradictory"}
            if rms:
                text += f"; GST RMS ignored on {sum(rms.values())} epochs (no range-residual RMS: " + ", ".join(
                    f"{n} {k}" for k, n in rms.items()) + ")"
            if ignored.get("contradictory"):
                text += (f"; GST ignored on {ignored['contradictory']} epochs (it contradicts itself: its ellipse and its "
                         f"σ's are not one covariance; no evidence)")  # fmt: skip
        if "receiver_notes" in summary:
            text += "; " + summary["receiver_notes"]["gpsd_json"].split(": the positions")[0]
        note(text, quiet)
    if stats.lines or kind in NAVIGATION_KINDS:  # (read as a navigation log)
        check_partial(stats, max_bad)
    elif max_bad is not None and counts["skipped", "lines"] > max_bad:
        raise PartialError(f"{run.name}: {counts['skipped', 'lines']} lines skipped, more than --max-bad {max_bad}; outputs were written")


def _stream_navigation_log(run, writer, params, sigma_model, sigma, nominal, strict, quiet, counts, stats, day=None, environment="auto",
          kind="nmea") -> None:
    with progress(f"checking {run.name}", quiet, log=run.log) as advance:
        for chunk in iter_integrity(run, kind, params, sigma_model, sigma, nominal, strict, stats, date=day,
                                    environment=environment):
            writer.write(chunk.table)
            tally_verdicts(chunk.table, counts)
            advance(len(chunk.table), int(chunk.table["line"].max()) if len(chunk.table) and "line" in chunk.table else None)
    check_usable(stats)
    note(stats.summary(), quiet)


