"""``tollcli epochs``: a receiver log → the epoch table (and the satellite table)."""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note, progress
from tollcli.errors import UsageError
from tollcli.io.log_run import LogRun
from tollcli.io.prefetch import read_ahead
from tollcli.io.writers import TableWriter, format_for
from tollcli.readers.navigation import NAVIGATION_KINDS, iter_epoch_tables
from tollcli.readers.nmea import ReadStats
from tollcli.readers.nmea.reader import check_partial, check_usable


def epochs(
    log: opt.LogArg,
    output: opt.Output = "-",
    out_fmt: opt.TableFormat = None,
    satellites: Annotated[
        Optional[str],
        typer.Option("--satellites", help="Also write the satellite table (one row per satellite and epoch) here (its format: its extension, else -f)."),
    ] = None,
    input_format: opt.InputFormat = "auto",
    nav: opt.Nav = None,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
    max_bad: opt.MaxBad = None,
    reader: Annotated[
        str,
        typer.Option("--reader", help="bulk (array decoding, the default) or reference (one line at a time: "
                     "slower, the same tables; for cross-checking a log)."),  # fmt: skip
    ] = "bulk",
) -> None:
    """Decode a receiver log (NMEA 0183, u-blox NAV messages, gpsd JSON) into one row per epoch.

    Columns carry their units (lat_deg, alt_m, speed_mps, ...). Lines that
    cannot be used are skipped and counted on stderr; --strict makes the first
    one an error. A pseudorange log (RINEX, GnssLogger, GSDC, u-blox RAWX,
    libRSF) gives the positions its pseudoranges solve to, epoch by epoch
    (snapshot weighted least squares; --nav for the orbits where the log has
    none), and --satellites a row per pseudorange used (angles, C/N0, σ,
    pre-fit residual).
    """
    out_fmt, fmt = opt.split_format(out_fmt, input_format)
    if reader not in ("bulk", "reference"):
        raise UsageError(f"--reader {reader}: bulk or reference")
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the table a file with -o")
    if satellites == "-" and output == "-":
        raise UsageError("only one table can go to stdout: give --satellites or -o a file")
    stats = ReadStats()
    epoch_writer = TableWriter(output, format_for(output, fmt=out_fmt))
    sat_writer = TableWriter(satellites, _sat_format(satellites, out_fmt)) if satellites else None
    with epoch_writer, (sat_writer or _Null()):
        with progress(f"reading {log}", quiet, log=log) as advance, LogRun(log, fmt, hashed=False) as run:  # the log opened once, not hashed: no invoice names it
            if run.kind not in NAVIGATION_KINDS:  # a pseudorange log
                solved = _solved(run, opt.nav_files(nav), strict, epoch_writer, sat_writer, quiet)
                if solved is not None:
                    _finish_solved(solved, epoch_writer, sat_writer, as_json, quiet, max_bad)
                    return
                from tollcli.job.solved_tables import receiver_fix_tables

                tables = receiver_fix_tables(run, strict, stats)  # its receiver's own fixes
            else:
                tables = iter_epoch_tables(run, strict=strict, date=date.date() if date else None, stats=stats, engine=reader,
                                           decode_ahead=True)  # reading is this command's whole work  # fmt: skip
            with read_ahead(tables) as chunks:  # the next chunk read while this one is written
                for chunk in chunks:
                    epochs = chunk.epoch_columns
                    epoch_writer.write(epochs)
                    if sat_writer is not None:
                        sat_writer.write(chunk.satellite_columns)
                    advance(len(epochs), int(epochs["line"].max()) if len(epochs) else None)
        check_usable(stats)
        if stats.epochs == 0:
            from tollcli.readers.nmea.tables import epoch_columns, satellite_columns

            epoch_writer.write(epoch_columns(None))
            if sat_writer is not None:
                sat_writer.write(satellite_columns(None, None))
        epoch_writer.commit()
        if sat_writer is not None:
            sat_writer.commit()
    if as_json:
        typer.echo(json.dumps(stats.as_dict(), sort_keys=True))
    else:
        note(stats.summary(), quiet)
    check_partial(stats, max_bad)


def _solved(run: LogRun, nav, strict: bool, epoch_writer: TableWriter, sat_writer: TableWriter | None, quiet: bool) -> dict | None:
    """A pseudorange log's solved epochs (and satellites) written; its summary. None: a u-blox log without the
    orbits to solve its pseudoranges but with its receiver's own fixes (NAV messages), which are read instead."""
    from tollcli.gnss.pseudorange_inputs import NoOrbitsError
    from tollcli.job.file_info import solutions_instead
    from tollcli.job.solved_tables import solved_tables

    with run.named_errors():
        try:
            epochs, satellite_rows = solved_tables(run.replay_path(), run.kind, nav, strict)
        except NoOrbitsError:
            if solutions_instead(run.replay_path(), run.kind, nav):
                note(f"{run.name}: no orbits to solve its pseudoranges (--nav gives them): its receiver's own fixes are read", quiet)
                return None
            raise
    epoch_writer.write(epochs)
    if sat_writer is not None:
        sat_writer.write(satellite_rows)
    return {"source": run.name, "format": run.kind, "epochs": len(epochs), "fixes": int(epochs["lat_deg"].notna().sum()),
            "pseudoranges": len(satellite_rows), "skipped_lines": int(epochs.attrs.get("skipped_lines", 0)),
            "solved_by": "tollcli (snapshot weighted least squares)"}  # fmt: skip


def _finish_solved(summary: dict, epoch_writer: TableWriter, sat_writer: TableWriter | None, as_json: bool, quiet: bool,
                   max_bad: int | None) -> None:  # fmt: skip
    """Commit a pseudorange log's tables and say what they hold (exit 3 beyond --max-bad skipped lines)."""
    from tollcli.errors import PartialError

    epoch_writer.commit()
    if sat_writer is not None:
        sat_writer.commit()
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True))
    else:
        skipped = f"; skipped {summary['skipped_lines']} malformed lines" if summary["skipped_lines"] else ""
        note(f"{summary['source']}: {summary['format']}, {summary['pseudoranges']} pseudoranges solved to {summary['fixes']} fixes "
             f"in {summary['epochs']} epochs{skipped}", quiet)  # fmt: skip
    if max_bad is not None and summary["skipped_lines"] > max_bad:
        raise PartialError(f"{summary['source']}: {summary['skipped_lines']} lines skipped, more than --max-bad {max_bad}; outputs were written")


def _sat_format(path: str, fmt: str | None) -> str:
    """The satellite table's format: its own extension, else -f, else CSV."""
    try:
        return format_for(path)
    except UsageError:
        if fmt:
            return format_for(path, fmt=fmt)
        raise


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None
