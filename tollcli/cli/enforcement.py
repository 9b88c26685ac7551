"""``tollcli locate``, ``tollcli findings`` and ``tollcli enforce``: the operator's enforcement and recovery tools."""

from __future__ import annotations

import datetime as dt
import json
from collections import Counter
from typing import Annotated, Optional

import pandas as pd
import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note
from tollcli.enforcement.findings import CLASS_MAX_SPEED_MPS, FindingSettings
from tollcli.enforcement.locate import (
    COLUMNS,
    latest_per_vehicle,
    locate_in,
    located_rows,
    separate_simultaneous,
    vehicle_from_path,
)
from tollcli.enforcement.roadside import RoadsideSettings
from tollcli.errors import UsageError
from tollcli.io.writers import TableWriter, format_for, write_text_atomic
from tollcli.job.trip_checks import locate_log, log_findings, roadside_findings

VehicleClass = Annotated[str, typer.Option("--vehicle-class", help=f"Vehicle class, sets the top speed: {', '.join(CLASS_MAX_SPEED_MPS)}.")]


def locate(
    logs: Annotated[list[str], typer.Argument(metavar="LOG...", help="Receiver logs (one or more vehicles).", show_default=False)],
    vehicle: Annotated[Optional[str], typer.Option("--vehicle", help="Vehicle id of a single log (default: a '# vehicle: ID' header line in the log, else the file name without extensions).")] = None,
    at: Annotated[Optional[dt.datetime], typer.Option("--at", formats=["%Y-%m-%dT%H:%M:%S", "%Y-%m-%dT%H:%M:%SZ", "%Y-%m-%dT%H:%M:%S.%fZ", "%Y-%m-%dT%H:%M:%S.%f", "%Y-%m-%d %H:%M:%S"], help="Where was it at this UTC time (the last position at or before it), as the outputs write it (2026-03-02T08:00:00.000Z) or without fraction and Z.")] = None,
    hal: opt.Hal = 50.0,
    output: opt.Output = "-",
    out_fmt: opt.TableFormat = None,
    as_json: Annotated[bool, typer.Option("--json", help="Write JSON records instead of a table (same as -f json).")] = False,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
) -> None:
    """The last trusted position of each vehicle (RAIM valid at --hal), and the last position of any kind when it differs.

    Columns: vehicle, log, which (last_trusted | last_any), time_utc, lat_deg,
    lon_deg, raim_status, hpl_m, hal_m, speed_mps, course_deg, line.
    """
    at_utc = pd.Timestamp(at).tz_localize("UTC") if at else None
    if vehicle and len(logs) > 1:
        raise UsageError("--vehicle names the vehicle of a single log; with several logs the file names give the ids")
    per_log, spans, headers = [], [], []
    for log in logs:
        table, header = locate_log(log, hal, strict, date)
        headers.append(header)
        dated = table["time_utc"].dropna() if "time_utc" in table else pd.Series(dtype=object)
        spans.append((dated.min(), dated.max()) if len(dated) else None)
        if table.empty:
            note(f"{log}: no epochs", quiet)
            per_log.append(None)
            continue
        found = locate_in(table, at_utc)
        if found["any"] is None:
            note(f"{log}: no position{' before ' + str(at_utc) if at_utc is not None else ''}", quiet)
        per_log.append(found)
    vehicles = [vehicle] if vehicle else [header or vehicle_from_path(log) for log, header in zip(logs, headers)]
    named_by_file = [not vehicle and header is None for header in headers]
    vehicles, notes = separate_simultaneous(vehicles, named_by_file, logs, spans)
    for line in notes:
        note(line, quiet)
    rows = [row for log, vid, found in zip(logs, vehicles, per_log) if found is not None for row in located_rows(vid, log, found)]
    rows = latest_per_vehicle(rows)
    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    kind = "json" if as_json else format_for(output, fmt=out_fmt)
    if kind == "json":
        records = [{k: (v.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z" if isinstance(v, pd.Timestamp) else v) for k, v in r.items()} for r in rows]
        write_text_atomic(output, json.dumps(records, indent=1) + "\n")
    else:
        with TableWriter(output, kind) as writer:
            writer.write(frame)
            writer.commit()
    trusted = sum(r["which"] == "last_trusted" for r in rows)
    note(f"{len(logs)} logs: {trusted} vehicles with a trusted position, {len(rows) - trusted} later untrusted positions", quiet)


def findings(
    log: opt.LogArg,
    geo: Annotated[Optional[str], typer.Option("--geo", help="Geo-objects: a gap lists those it could have crossed.")] = None,
    vehicle_class: VehicleClass = "car",
    hal: opt.Hal = 50.0,
    osnma_merkle: opt.OsnmaMerkle = None,
    osnma_public_key: opt.OsnmaPublicKey = None,
    output: opt.FindingsOutput = "-",
    out_fmt: opt.FindingsFormat = None,
    max_speed: Annotated[Optional[float], typer.Option("--max-speed", help="Top speed, m/s (overrides --vehicle-class).", min=1.0)] = None,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
    gap_min: Annotated[float, typer.Option("--gap-min", help="A gap lasts at least this long, s.", min=1.0)] = 60.0,
    gap_min_distance: Annotated[float, typer.Option("--gap-min-distance", help="…and ends at least this far away, m.", min=0.0)] = 500.0,
    as_json: opt.JsonSummary = False,
) -> None:
    """Tamper and evasion findings of one trip (gaps, jamming signs, spoofing signs), with times, positions and evidence.

    A u-blox log with Galileo I/NAV pages and the OSNMA Merkle tree beside it (or
    --osnma-merkle) is authenticated too: each failure (a tag, key or signature
    that does not verify) is an osnma_failure finding naming satellite and time.

    Writes JSON: the settings used and one record per finding (kind, category,
    start_utc, end_utc, lat_deg, lon_deg, end_lat_deg, end_lon_deg, evidence);
    with -f csv, geojson or geojsonseq one row or point per finding (evidence as JSON text).
    """
    kind = _findings_format(output, out_fmt, as_json)
    overrides = {"gap_min_s": gap_min, "gap_min_m": gap_min_distance}
    if max_speed is not None:  # the given top speed serves any class name
        overrides["max_speed_mps"] = max_speed
    settings = FindingSettings.for_class(vehicle_class, **overrides)
    items = log_findings(log, settings, hal, strict, date, geo, osnma_merkle, osnma_public_key)
    doc = {"log": log, "settings": settings.__dict__, "findings": items}
    _write_findings(output, kind, doc)
    _findings_summary(log, output, items, "findings", quiet, as_json)


def enforce(
    log: opt.LogArg,
    reads: Annotated[str, typer.Option("--reads", help="Tag reads CSV: tag_id, gantry_id, time_utc.")],
    gantries: Annotated[str, typer.Option("--gantries", help="Gantries GeoJSON: Point or LineString features with an id.")],
    tag: Annotated[Optional[str], typer.Option("--tag", help="The vehicle's tag id (default: every read in the file).")] = None,
    time_tol: Annotated[float, typer.Option("--time-tol", help="A read and a fix match within this many seconds.", min=0.0)] = 30.0,
    distance_tol: Annotated[float, typer.Option("--distance-tol", help="A read this far from the trip is a finding, m.", min=0.0)] = 1000.0,
    pass_dist: Annotated[float, typer.Option("--pass-dist", help="The trip passes a gantry within this distance, m.", min=0.0)] = 50.0,
    output: opt.FindingsOutput = "-",
    out_fmt: opt.FindingsFormat = None,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    hal: opt.Hal = 50.0,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
) -> None:
    """Cross-check RFID/DSRC gantry reads with the GNSS trip: reads where the trip was elsewhere or silent, gantries passed without a read."""
    kind = _findings_format(output, out_fmt, as_json)
    items = roadside_findings(log, reads, gantries, tag, RoadsideSettings(time_tol, distance_tol, pass_dist), hal, strict, date)
    doc = {"log": log, "tag": tag, "settings": {"time_tol_s": time_tol, "distance_tol_m": distance_tol, "pass_dist_m": pass_dist},
           "findings": items}  # fmt: skip
    _write_findings(output, kind, doc)
    _findings_summary(log, output, items, "roadside findings", quiet, as_json)


def _findings_format(output: str, fmt: str | None, as_json: bool) -> str:
    """The findings' format (JSON, or a table of them); --json needs the findings in a file."""
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the findings a file with -o")
    return format_for(output, "json", fmt, ("json", "csv", "geojson", "geojsonseq"))


def _write_findings(output: str, kind: str, doc: dict) -> None:
    """The findings document as JSON, or its findings one per row or point (evidence as JSON text)."""
    if kind == "json":
        write_text_atomic(output, json.dumps(doc, indent=1, sort_keys=True) + "\n")
        return
    rows = [{k: (json.dumps(v, sort_keys=True) if isinstance(v, (dict, list)) else v) for k, v in f.items()} for f in doc["findings"]]
    first = ["kind", "category", "start_utc", "end_utc", "lat_deg", "lon_deg", "end_lat_deg", "end_lon_deg"]
    columns = first + sorted({k for r in rows for k in r} - set(first))
    with TableWriter(output, kind) as writer:
        writer.write(pd.DataFrame(rows, columns=columns))
        writer.commit()


def _findings_summary(log: str, output: str, items: list, what: str, quiet: bool, as_json: bool) -> None:
    """The closing line on stderr, or with --json the counts on stdout."""
    kinds = Counter(f["kind"] for f in items)
    if as_json:
        typer.echo(json.dumps({"log": log, "output": output, "findings": len(items), "kinds": dict(sorted(kinds.items()))}, sort_keys=True))
        return
    note(f"{log}: {len(items)} {what}" + (": " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())) if items else ""), quiet)
