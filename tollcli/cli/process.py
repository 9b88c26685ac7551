"""``tollcli process``: a receiver log → the invoice (the main job)."""

from __future__ import annotations

import os
import sys
from typing import Annotated, Optional

import typer

from tollcli.charging.invoice import build_invoice, file_sha256, invoice_csv, invoice_json
from tollcli.charging.recognition import charges, load_geoobjects, recognise
from tollcli.charging.tariffs import load_tariff
from tollcli.cli import options as opt
from tollcli.cli.console import warn
from tollcli.cli.epochs import check_usable
from tollcli.cli.integrity import sniff_format
from tollcli.errors import UsageError
from tollcli.integrity.from_nmea import nmea_measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.sigma_models import NominalModel
from tollcli.io.writers import write_text_atomic
from tollcli.nmea import read_nmea


def process(
    log: opt.LogArg,
    geo: Annotated[str, typer.Option("--geo", help="Geo-objects (GeoJSON from 'tollcli geoobjects build').")],
    tariff: Annotated[str, typer.Option("--tariff", help="Tariff (TOML).")],
    vehicle_class: Annotated[str, typer.Option("--vehicle-class", help="Vehicle class in the tariff.")] = "car",
    vehicle: Annotated[Optional[str], typer.Option("--vehicle", help="Vehicle id (default: the log's file name).")] = None,
    output: opt.Output = "-",
    nav: Annotated[Optional[str], typer.Option("--nav", help="RINEX navigation file (RINEX input).")] = None,
    raim: opt.RaimMode = "etc",
    p_md: opt.PMd = 5e-5,
    p_fa: opt.PFa = 5e-3,
    fde: opt.Fde = False,
    sigma_model: opt.SigmaModel = "nominal",
    sigma: opt.Sigma = 5.0,
    tc: Annotated[float, typer.Option("--tc", help="Correlation time: independent positions are at least this far apart, s.", min=0.0)] = 5.0,
    n_th: Annotated[int, typer.Option("--n-th", help="Charge when at least this many valid independent positions fell inside.", min=1)] = 1,
    strict: opt.Strict = False,
    date: opt.DateOpt = None,
    quiet: opt.Quiet = False,
) -> None:
    """Charge a trip: valid, independent positions inside geo-objects → invoice lines with evidence.

    The invoice (JSON by default; .csv with -o file.csv; a table on a terminal)
    lists each charged geo-object passage with its fee, entry and exit times and
    the positions that support it, the passages seen but not charged, the input
    files' SHA-256 and every parameter used.
    """
    if output != "-" and not output.lower().endswith((".json", ".csv")):
        raise UsageError(f"{output}: invoices are written as .json or .csv")
    try:
        params = RaimParams(mode=raim, p_md=p_md, p_fa=p_fa, fde=fde)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    geo_objects = load_geoobjects(geo)
    tariff_doc = load_tariff(tariff)
    kind = sniff_format(log)
    if kind == "nmea":
        tables = read_nmea(log, strict=strict, date=date.date() if date else None)
        check_usable(tables.stats)
        epochs = tables.epochs
        meas = nmea_measurements(epochs, tables.satellites, sigma_model if sigma_model != "input" else "nominal", sigma, NominalModel())
    elif kind == "gsdc-derived":
        from tollcli.integrity.gsdc import gsdc_epochs, read_gsdc_derived

        epochs, meas = gsdc_epochs(read_gsdc_derived(log), sigma_model, sigma, NominalModel())
    else:
        from tollcli.integrity.rinex import rinex_epochs

        if nav is None:
            raise UsageError("RINEX input needs --nav NAVFILE")
        epochs, meas = rinex_epochs(log, nav, sigma_model, sigma, NominalModel())
    positions = recognise(epochs, meas, geo_objects, params, tc_s=tc, n_th=n_th)
    table = charges(positions, n_th)
    dated = epochs["time_utc"].dropna()
    inputs = {"log": os.path.basename(log), "geoobjects": os.path.basename(geo), "tariff": os.path.basename(tariff)}
    if log != "-":
        inputs["log_sha256"] = file_sha256(log)
    inputs.update(geoobjects_sha256=file_sha256(geo), tariff_sha256=file_sha256(tariff))
    parameters = {"raim": raim, "p_md": p_md, "p_fa": p_fa if raim == "classic" else None, "fde": fde, "tc_s": tc,
                  "n_th": n_th, "sigma_model": sigma_model, "valid_statuses": ["valid", "excluded_valid"]}  # fmt: skip
    invoice = build_invoice(table, positions, geo_objects, tariff_doc, vehicle=vehicle or os.path.basename(log),
                            vehicle_class=vehicle_class, inputs=inputs, parameters=parameters,
                            period=(dated.min(), dated.max()) if len(dated) else None)  # fmt: skip
    if output == "-" and sys.stdout.isatty():
        _table(invoice)
    else:
        write_text_atomic(output, invoice_csv(invoice) if output.lower().endswith(".csv") else invoice_json(invoice))
    warn(f"{log}: {len(invoice['lines'])} charged, {len(invoice['not_charged'])} seen but not charged, "
         f"total {invoice['total']} {invoice['currency']}", quiet)  # fmt: skip


def _table(invoice: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"Invoice {invoice['vehicle']} ({invoice['vehicle_class']})")
    for col in ("geo-object", "entry (UTC)", "exit (UTC)", "positions", "band", f"fee {invoice['currency']}"):
        table.add_column(col)
    for line in invoice["lines"]:
        table.add_row(line["geoobject"], line["entry_utc"], line["exit_utc"], str(line["n_valid_independent"]), line["band"], line["fee"])
    table.add_row("TOTAL", "", "", "", "", invoice["total"])
    Console().print(table)


