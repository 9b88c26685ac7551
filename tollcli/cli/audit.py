"""``tollcli audit``: invoices against the truth (under/overcharges), or a risk report without it."""

from __future__ import annotations

import glob
import json
import os
import sys
from collections import Counter
from typing import Annotated, Optional

import pandas as pd
import typer

from tollcli.charging.audit import (
    MONEY_UNKNOWN,
    audit_with_truth,
    check_same_trip,
    findings_of,
    load_invoice,
    risk_report,
    start_time_of,
)
from tollcli.charging.recognition import load_geoobjects
from tollcli.charging.tariffs import load_tariff
from tollcli.charging.truth_passages import is_id_list, truth_passages, truth_trajectory
from tollcli.cli import options as opt
from tollcli.cli.console import audit_tables, note, show
from tollcli.errors import DataError, UsageError
from tollcli.integrity.truth_check import check_against_truth
from tollcli.io.sources import read_table
from tollcli.io.writers import write_text_atomic
from tollcli.job.verify import VerifyFailed, locate_input


def _expand(runs: list[str]) -> list[tuple[str, dict]]:
    """The invoices named: files, globs, or folders searched recursively (a batch output folder: its
    ``invoices/<vehicle>/*.json``); in a folder, JSON files that are not invoices (a summary) are passed over."""
    found: list[tuple[str, dict]] = []
    for run in runs:
        if os.path.isdir(run):
            for path in sorted(glob.glob(os.path.join(glob.escape(run), "**", "*.json"), recursive=True)):
                try:
                    found.append((path, load_invoice(path)))
                except DataError:
                    continue
        elif any(ch in run for ch in "*?["):
            found.extend((p, load_invoice(p)) for p in sorted(glob.glob(run)))
        else:
            found.append((run, load_invoice(run)))
    if not found:
        raise UsageError("no invoices found in " + ", ".join(runs))
    return found


class TariffPricer:
    """The true fee of a passage: the tariff (``--tariff``, else the one each invoice records, found where it names
    it or beside it with its recorded SHA-256) at the passage's entry time, for the invoice's vehicle."""

    def __init__(self, found: list[tuple[str, dict]], tariff: str | None, geo: str | None, vehicle_class: str | None,
                 vehicle_attrs: dict | None):  # fmt: skip
        self.path_of = {id(inv): path for path, inv in found}  # where each invoice is (its tariff may lie beside it)
        self.tariff, self.geo, self.vehicle_class, self.vehicle_attrs = tariff, geo, vehicle_class, vehicle_attrs
        self.cache: dict[tuple, tuple] = {}
        self.sources: set[str] = set()

    def _load(self, invoice: dict, name: str):
        inputs = invoice.get("inputs") or {}
        tariff, geo = self.tariff, self.geo
        try:
            if tariff is None:
                tariff = locate_input(name, str(inputs["tariff"]), inputs.get("tariff_sha256"), "tariff")
            if geo is None:
                geo = locate_input(name, str(inputs["geoobjects"]), inputs.get("geoobjects_sha256"), "geo-objects")
        except (KeyError, VerifyFailed):
            return None
        key = (tariff, geo)
        if key not in self.cache:
            geo_objects = load_geoobjects(geo)
            doc = load_tariff(tariff)
            doc.check_against(geo_objects.ids, geo_objects.road_class, geo)
            index = {str(g): i for i, g in enumerate(geo_objects.ids)}
            self.cache[key] = (doc, geo_objects, index)
        self.sources.add(tariff)
        return self.cache[key]

    def __call__(self, invoice: dict, gid: str, when):
        loaded = self._load(invoice, self.path_of.get(id(invoice), ""))
        if loaded is None:
            return None
        doc, geo_objects, index = loaded
        if gid not in index:
            return None
        i = index[gid]
        if when is None:
            when = pd.Timestamp((invoice.get("period") or {}).get("start_utc", "2000-01-01T12:00:00Z"))
        vehicle = {**(invoice.get("vehicle_attributes") or {}), **(self.vehicle_attrs or {}),
                   "vehicle_class": self.vehicle_class or invoice.get("vehicle_class") or "car"}  # fmt: skip
        length_m = float(geo_objects.length_m[i]) if geo_objects.length_m is not None else None
        return doc.price(gid, str(geo_objects.road_class[i]), length_m, vehicle, when.to_pydatetime()).fee


def audit(
    runs: Annotated[Optional[list[str]], typer.Argument(metavar="[RUN...]", help="Invoices (JSON from 'tollcli process'), folders or globs.", show_default=False)] = None,
    truth: Annotated[Optional[str], typer.Option("--truth", help="Driven geo-objects: ids (JSON list or one per line) or a trajectory (CSV/GeoJSON, needs --geo).")] = None,
    geo: Annotated[Optional[str], typer.Option("--geo", help="Geo-objects, to read a truth trajectory and price missed ones.")] = None,
    tariff: Annotated[Optional[str], typer.Option("--tariff", help="Tariff to price the passages driven (default: the one each invoice records, where it names it or beside it, checked by its SHA-256).")] = None,
    vehicle_class: Annotated[Optional[str], typer.Option("--vehicle-class", help="Vehicle class to price passages at (default: each invoice's).")] = None,
    vehicle_attr: opt.VehicleAttr = None,
    invoice_error: Annotated[float, typer.Option("--invoice-error", help="M_e: an invoice is right when within this percentage of the true total.", min=0.0)] = 1.0,
    epochs: Annotated[Optional[str], typer.Option("--epochs", help="An integrity epoch table ('tollcli integrity -o', CSV/Parquet): with a --truth trajectory, count positioning failures and those the RAIM missed.")] = None,
    output: opt.JsonOutput = "-",
    out_fmt: opt.out_format("json", "json") = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
) -> None:
    """Count undercharges (driven, not charged) and overcharges (charged, not driven) with rates and 95 % intervals.

    Without --truth: revenue at risk (fixes inside, too few valid positions, and
    why) and for each charge a bound on the chance that it is false.
    """
    if not runs and not epochs:
        raise UsageError("give invoices (RUN...) and/or --epochs with --truth")
    if out_fmt is not None and out_fmt.lower() != "json":
        raise UsageError(f"-f {out_fmt}: the audit report is JSON")
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the report a file with -o")
    integrity = None
    if epochs:
        if not truth or is_id_list(truth):
            raise UsageError("--epochs needs --truth to be a trajectory (CSV with time_utc, lat_deg, lon_deg)")
        integrity = check_against_truth(read_table(epochs), truth_trajectory(truth))
    if not runs:
        report = {"mode": "integrity", "integrity": integrity}
        summary = integrity_words(integrity)
        _emit(report, summary, output, quiet, as_json)
        return
    found = _expand(runs)
    paths = [p for p, _ in found]
    invoices = [inv for _, inv in found]
    if any(inv.get("scheme") == "city" for inv in invoices):
        _audit_city(found, truth, geo, tariff, vehicle_class, opt.vehicle_attrs(vehicle_attr), output, quiet, as_json)
        return
    start_time = start_time_of(invoices, paths)  # a relative-clock truth is placed where the invoices placed the log
    if truth:
        check_same_trip(invoices, paths, truth, start_time)
    geo_objects = load_geoobjects(geo) if geo else None
    if tariff and geo_objects is None:
        raise UsageError("--tariff prices geo-objects by their road class: give --geo too")
    pricer = TariffPricer(found, tariff, geo, vehicle_class, opt.vehicle_attrs(vehicle_attr))
    if truth:
        if geo_objects is None and not is_id_list(truth):
            raise UsageError("a truth trajectory needs --geo to know where the geo-objects are")
        passages = truth_passages(truth, geo_objects, start_time)
        report = {"mode": "truth", **audit_with_truth(invoices, passages, {}, invoice_error, pricer)}
        if report["share_within"] is None:
            money = f"money unknown ({MONEY_UNKNOWN})"
        else:
            money = f"{report['share_within']:.1%} of {report['runs_money_known']} invoices within {invoice_error:g} %"
        summary = (f"{report['runs']} runs, {report['passages_driven']} passages driven: {report['missed_recognitions']} "
                   f"missed recognitions, {report['false_recognitions']} false recognitions; {money}")  # fmt: skip
    else:
        report = {"mode": "risk", **risk_report(invoices, {}, pricer)}
        summary = (f"{report['runs']} runs: {len(report['revenue_at_risk'])} passages at risk "
                   f"({report['money_at_risk']}{'' if report['money_at_risk_complete'] else ' or more'} not charged), "
                   f"{len(report['charges'])} charges")  # fmt: skip
    report["tariffs"] = sorted(pricer.sources)
    report["findings"] = findings_of(invoices)
    if report["findings"]:
        kinds = Counter(f["kind"] for f in report["findings"])
        summary += "; findings: " + ", ".join(f"{n} {k}" for k, n in sorted(kinds.items()))
    if integrity is not None:
        report["integrity"] = integrity
        summary += f"; {integrity['positioning_failures']} positioning failures, {integrity['undetected']} undetected"
    _emit(report, summary, output, quiet, as_json)


def _audit_city(found: list[tuple[str, dict]], truth, geo, tariff, vehicle_class, attrs, output, quiet, as_json) -> None:
    """City invoices (gantries, zones) against a truth trajectory: crossings and zone presences, rules, day totals."""
    from tollcli.charging.city_audit import city_audit
    from tollcli.charging.city_tariff import load_city_tariff
    from tollcli.geoobjects.city import load_city_network

    invoices = [inv for _, inv in found]
    if any(inv.get("scheme") != "city" for inv in invoices):
        raise UsageError("city invoices (gantries, zones) are audited on their own: do not mix them with section invoices")
    if not truth or is_id_list(truth):
        raise UsageError("a city invoice is audited against a truth trajectory (--truth CSV with time_utc, lat_deg, lon_deg)")
    first_path, first = found[0]
    inputs = first.get("inputs") or {}
    try:
        geo = geo or locate_input(first_path, str(inputs["geoobjects"]), inputs.get("geoobjects_sha256"), "geo-objects")
        tariff = tariff or locate_input(first_path, str(inputs["tariff"]), inputs.get("tariff_sha256"), "tariff")
    except KeyError:
        raise UsageError(f"{first_path}: give --geo and --tariff (the invoice does not name them)") from None
    net, doc = load_city_network(geo), load_city_tariff(tariff)
    attrs = {**((first.get("parameters") or {}).get("vehicle_attrs") or {}), **(attrs or {})}
    vehicle = vehicle_class or first.get("vehicle_class") or "car"
    report = {"mode": "city_truth", "runs": len(invoices), "tariffs": [tariff],
              **city_audit(invoices, net, doc, truth_trajectory(truth, start_time_of(invoices, [p for p, _ in found])), vehicle, attrs)}  # fmt: skip
    summary = (f"{report['runs']} runs: {report['crossings_driven']} crossings driven, {len(report['missed'])} missed, "
               f"{len(report['false'])} false; {report['zone_presences_driven']} zone presences driven; total invoiced "
               f"{report['invoiced_total']} of {report['truth_total']} {report['currency']} owed (undercharge "
               f"{report['undercharge']}, overcharge {report['overcharge']})")  # fmt: skip
    opt.require_json(output)
    text = json.dumps(report, indent=2, sort_keys=True, default=str) + "\n"
    if output == "-" and sys.stdout.isatty():
        typer.echo(summary)
    else:
        write_text_atomic(output, text)
    if as_json:
        typer.echo(json.dumps({"output": output, "mode": report["mode"], "summary": summary, "undercharge": report["undercharge"],
                               "overcharge": report["overcharge"], "missed": len(report["missed"]), "false": len(report["false"])},
                              sort_keys=True))  # fmt: skip
    else:
        note(summary, quiet)


def integrity_words(integrity: dict) -> str:
    """The integrity audit in one line: availability first (nothing valid misleads nobody and charges nothing), then
    the failures and how many the checks missed (no rate without a failure to miss)."""
    n, valid = integrity["with_position"], integrity["valid"]
    share = f"{valid / n:.1%}" if n else "—"
    rate = f"rate {integrity['undetected_rate']:.2e}" if integrity["undetected_rate"] is not None else "no positioning failure to miss"
    return (f"{n} positions: {valid} valid ({share} available), {integrity['regions']['misleading']} misleading, "
            f"{integrity['positioning_failures']} positioning failures, {integrity['undetected']} undetected "
            f"({rate}, P_MD {integrity['p_md']:g})")  # fmt: skip


def _emit(report: dict, summary: str, output: str, quiet: bool, as_json: bool = False) -> None:
    opt.require_json(output)
    text = json.dumps(report, indent=2, sort_keys=True, default=str) + "\n"
    to_stdout = output == "-" and sys.stdout.isatty()
    show(lambda: audit_tables(report), quiet if not to_stdout else False, to_stdout=to_stdout)
    if to_stdout:
        typer.echo(summary)
    else:
        write_text_atomic(output, text)
    if as_json:
        typer.echo(json.dumps({"output": output, "mode": report["mode"], "summary": summary,
                               **{k: report[k] for k in AUDIT_SUMMARY_KEYS if k in report}}, sort_keys=True, default=str))
    else:
        note(summary, quiet)


#: the report's figures ``--json`` repeats on stdout
AUDIT_SUMMARY_KEYS = ("runs", "passages_driven", "missed_recognitions", "false_recognitions", "share_within",
                      "money_at_risk", "money_at_risk_complete")




