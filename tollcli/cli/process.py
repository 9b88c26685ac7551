"""``tollcli process``: a receiver log → the invoice (the main job)."""

from __future__ import annotations

import json
import sys
from typing import Annotated, Optional

import typer

from tollcli.charging.invoice import invoice_csv, invoice_json
from tollcli.cli import options as opt
from tollcli.cli.charge_options import ChargeOptions, charge_options
from tollcli.cli.console import invoice_tables, note, show
from tollcli.cli.settings_file import Config
from tollcli.errors import UsageError
from tollcli.io.writers import format_for, write_text_atomic
from tollcli.job.pipeline import charge_log
from tollcli.readers.nmea.reader import check_partial


@charge_options
def process(
    log: opt.LogArg,
    vehicle: Annotated[Optional[str], typer.Option("--vehicle", help="Vehicle id (default: the log's file name).")] = None,
    output: opt.InvoiceOutput = "-",
    out_fmt: opt.InvoiceFormat = None,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
    config: Config = None,
    *,
    charge: ChargeOptions,
) -> None:
    """Charge a trip: valid, independent positions inside geo-objects → invoice lines with evidence.

    The invoice (JSON by default; -f csv or -o file.csv: one row per line, with
    vehicle, log and currency, the total only in the JSON; a table on a terminal)
    lists each charged geo-object passage with its fee (with a per-km tariff: the
    table in force, the length charged and the rate), entry and exit times and
    the positions that support it, the passages seen but not charged, the input
    files and their SHA-256, every parameter used, and the SHA-256 of its own
    content; 'tollcli verify' re-runs it. A u-blox log with Galileo I/NAV pages
    and the OSNMA Merkle tree beside it (or --osnma-merkle) is authenticated:
    each position and line says whether its navigation data were authenticated,
    each OSNMA failure is an osnma_failure finding (see docs/osnma.md).
    """
    out_fmt, fmt = opt.split_format(out_fmt, charge.input_format)
    kind = format_for(output, "json", out_fmt, ("json", "csv"))
    if as_json and output == "-":
        raise UsageError("--json prints the summary on stdout: give the invoice a file with -o")
    invoice, stats = charge_log(log, charge.geo, charge.tariff, charge.settings(vehicle, fmt), charge.nav, charge.roads,
                                osnma_merkle=charge.osnma_merkle, osnma_public_keys=charge.osnma_public_key)  # fmt: skip
    if output == "-" and out_fmt is None and sys.stdout.isatty():
        show(lambda: invoice_tables(invoice), False, to_stdout=True)
    else:
        write_text_atomic(output, invoice_csv(invoice) if kind == "csv" else invoice_json(invoice))
        show(lambda: invoice_tables(invoice), quiet or as_json)
    if as_json:
        typer.echo(json.dumps(invoice_summary(invoice, output, stats), sort_keys=True))
    else:
        note(f"{log}: {len(invoice['lines'])} charged, {len(invoice['not_charged'])} seen but not charged{_why_not(invoice)}, "
             f"total {invoice['total']} {invoice['currency']}{_checks_said(invoice)}{_nothing_seen(invoice)}{_rules_said(invoice)}", quiet)  # fmt: skip
    if stats is not None:
        check_partial(stats, charge.max_bad)


def invoice_summary(invoice: dict, output: str, stats=None) -> dict:
    """What ``--json`` prints: the invoice's totals and where it went (the invoice itself is in the file)."""
    return {"output": output, "vehicle": invoice["vehicle"], "log": invoice["inputs"].get("log"),
            "charged": len(invoice["lines"]), "not_charged": len(invoice["not_charged"]),
            "total": invoice["total"], "currency": invoice["currency"], "content_sha256": invoice["content_sha256"],
            "integrity_sources_used": invoice["parameters"].get("integrity_sources_used"),
            "policy_used": invoice["parameters"].get("policy_used"), "findings": len((invoice.get("findings") or {}).get("items") or []),
            "skipped_lines": int(stats.skipped) if stats is not None else 0}


def _rules_said(invoice: dict) -> str:
    """A city invoice's rules as they applied (single-charge, daily cap, free days …)."""
    rules = invoice.get("rules") or []
    return "; " + "; ".join(r["said"] for r in rules) if rules else ""


def _nothing_seen(invoice: dict) -> str:
    """For an invoice that saw no geo-object: how far the track stayed from the network."""
    from tollcli.charging.nothing_seen import nothing_seen_words

    report = invoice.get("nothing_seen")
    return f"; nothing seen: {nothing_seen_words(report)}" if report else ""


def _checks_said(invoice: dict) -> str:
    """How many evidence positions of the charged lines each check confirmed (the policy's checks only)."""
    evidence = sum(len(line.get("evidence", [])) for line in invoice["lines"] if "checks" in line)
    if not evidence:
        return ""
    confirmed: dict[str, int] = {}
    for line in invoice["lines"]:
        for check, n in (line.get("checks") or {}).get("confirmed", {}).items():
            confirmed[check] = confirmed.get(check, 0) + n
    policy = (invoice.get("parameters") or {}).get("policy_used", "")
    checks = sorted({*confirmed, *(["speed"] if policy in ("raim+speed", "all") else []),
                     *(["map_matching"] if policy in ("raim+mm", "all") else [])})  # fmt: skip
    said = ", ".join(f"{check.replace('_', ' ')} {confirmed.get(check, 0)}" for check in checks)
    return f"; of {evidence} evidence positions the checks confirmed: {said} (the rest: the RAIM's verdict alone, see each line's checks)"


def _why_not(invoice: dict) -> str:
    """The commonest reason positions of the passages not charged failed, as the invoice's note says it."""
    counts: dict[str, int] = {}
    for passage in invoice["not_charged"]:
        for status, n in passage["statuses"].items():
            if status not in ("valid", "excluded_valid"):
                counts[status] = counts.get(status, 0) + int(n)
    if not counts:
        return ""
    top = max(sorted(counts), key=counts.get)
    meaning = (invoice.get("status_notes") or {}).get(top, "")
    return f" (mostly {top}{': ' + meaning.split('. ')[0] if meaning else ''})"
