"""``tollcli audit``: invoices against the truth (under/overcharges), or a risk report without it."""

from __future__ import annotations

import glob
from collections import Counter
import json
import os
import sys

from typing import Annotated, Optional

import pandas as pd
import typer

from tollcli.charging.audit import audit_with_truth, check_same_trip, findings_of, driven_from_truth, fee_table, load_invoice, risk_report
from tollcli.charging.recognition import load_geoobjects
from tollcli.charging.tariffs import load_tariff
from tollcli.cli import options as opt
from tollcli.cli.console import audit_tables, show, warn
from tollcli.errors import UsageError
from tollcli.integrity.truth_check import check_against_truth
from tollcli.io.sources import read_table
from tollcli.io.writers import write_text_atomic


def _expand(runs: list[str]) -> list[str]:
    paths: list[str] = []
    for run in runs:
        if os.path.isdir(run):
            paths.extend(sorted(glob.glob(os.path.join(run, "*.json"))))
        elif any(ch in run for ch in "*?["):
            paths.extend(sorted(glob.glob(run)))
        else:
            paths.append(run)
    if not paths:
        raise UsageError("no invoices found in " + ", ".join(runs))
    return paths


def audit(
    runs: Annotated[Optional[list[str]], typer.Argument(metavar="[RUN...]", help="Invoices (JSON from 'tollcli process'), folders or globs.", show_default=False)] = None,
    truth: Annotated[Optional[str], typer.Option("--truth", help="Driven geo-objects: ids (JSON list or one per line) or a trajectory (CSV/GeoJSON, needs --geo).")] = None,
    geo: Annotated[Optional[str], typer.Option("--geo", help="Geo-objects, to read a truth trajectory and price missed ones.")] = None,
    tariff: Annotated[Optional[str], typer.Option("--tariff", help="Tariff, to price geo-objects no invoice charged.")] = None,
    vehicle_class: Annotated[str, typer.Option("--vehicle-class", help="Vehicle class for --tariff prices.")] = "car",
    vehicle_attr: opt.VehicleAttr = None,
    invoice_error: Annotated[float, typer.Option("--invoice-error", help="M_e: an invoice is right when within this %% of the true total.", min=0.0)] = 1.0,
    epochs: Annotated[Optional[str], typer.Option("--epochs", help="An integrity epoch table ('tollcli integrity -o', CSV/Parquet): with a --truth trajectory, count positioning failures and those the RAIM missed.")] = None,
    output: opt.JsonOutput = "-",
    quiet: opt.Quiet = False,
) -> None:
    """Count undercharges (driven, not charged) and overcharges (charged, not driven) with rates and 95 % intervals.

    Without --truth: revenue at risk (fixes inside, too few valid positions, and
    why) and for each charge a bound on the chance that it is false.
    """
    if not runs and not epochs:
        raise UsageError("give invoices (RUN...) and/or --epochs with --truth")
    integrity = None
    if epochs:
        if not truth or _is_id_list(truth):
            raise UsageError("--epochs needs --truth to be a trajectory (CSV with time_utc, lat_deg, lon_deg)")
        integrity = check_against_truth(read_table(epochs), read_table(truth))
    if not runs:
        report = {"mode": "integrity", "integrity": integrity}
        summary = (f"{integrity['with_position']} positions: {integrity['positioning_failures']} positioning failures, "
                   f"{integrity['undetected']} undetected (rate {integrity['undetected_rate']:.2e}, P_MD {integrity['p_md']:g})")  # fmt: skip
        _emit(report, summary, output, quiet)
        return
    paths = _expand(runs)
    invoices = [load_invoice(p) for p in paths]
    if truth:
        check_same_trip(invoices, paths, truth)
    fees = fee_table(invoices)
    geo_objects = load_geoobjects(geo) if geo else None
    if tariff:
        if geo_objects is None:
            raise UsageError("--tariff prices geo-objects by their road class: give --geo too")
        tariff_doc = load_tariff(tariff)
        tariff_doc.check_against(geo_objects.ids, geo_objects.road_class, geo)
        start = next((inv["period"]["start_utc"] for inv in invoices if inv.get("period")), "2000-01-01T12:00:00Z")
        when = pd.Timestamp(start).to_pydatetime()
        vehicle = {**(opt.vehicle_attrs(vehicle_attr) or {}), "vehicle_class": vehicle_class}
        lengths = geo_objects.length_m if geo_objects.length_m is not None else [None] * len(geo_objects.ids)
        for gid, road_class, length_m in zip(geo_objects.ids, geo_objects.road_class, lengths):
            if str(gid) not in fees:
                fees[str(gid)] = tariff_doc.price(str(gid), str(road_class), length_m, vehicle, when).fee
    if truth:
        if geo_objects is None and not _is_id_list(truth):
            raise UsageError("a truth trajectory needs --geo to know where the geo-objects are")
        driven = driven_from_truth(truth, geo_objects)
        report = {"mode": "truth", **audit_with_truth(invoices, driven, fees, invoice_error)}
        summary = (f"{report['runs']} runs: {report['missed_recognitions']} missed recognitions, "
                   f"{report['false_recognitions']} false recognitions, {report['share_within']:.1%} of invoices "
                   f"within {invoice_error:g} %")  # fmt: skip
    else:
        report = {"mode": "risk", **risk_report(invoices, fees)}
        summary = (f"{report['runs']} runs: {len(report['revenue_at_risk'])} passages at risk "
                   f"({report['money_at_risk']} not charged), {len(report['charges'])} charges")  # fmt: skip
    report["findings"] = findings_of(invoices)
    if report["findings"]:
        kinds = Counter(f["kind"] for f in report["findings"])
        summary += "; findings: " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items()))
    if integrity is not None:
        report["integrity"] = integrity
        summary += f"; {integrity['positioning_failures']} positioning failures, {integrity['undetected']} undetected"
    _emit(report, summary, output, quiet)


def _emit(report: dict, summary: str, output: str, quiet: bool) -> None:
    opt.require_json(output)
    text = json.dumps(report, indent=2, sort_keys=True, default=str) + "\n"
    to_stdout = output == "-" and sys.stdout.isatty()
    show(lambda: audit_tables(report), quiet if not to_stdout else False, to_stdout=to_stdout)
    if to_stdout:
        typer.echo(summary)
    else:
        write_text_atomic(output, text)
    warn(summary, quiet)


def _is_id_list(path: str) -> bool:
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096).lstrip()
    except OSError:
        return True  # let the reader report it
    first = head.splitlines()[0] if head else ""
    return head.startswith("[") or ("lat" not in first.lower() and not head.startswith("{"))


