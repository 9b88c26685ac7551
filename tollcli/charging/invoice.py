"""Invoices: one line per charged geo-object passage, with fee, times and the evidence behind it.

Shaped after an ISO 17575 charge report: detected charge objects with usage
evidence. Money is Decimal, written as strings; the document carries the tool
version, the input files' SHA-256 and the parameters, and contains no wall-clock
time, so the same inputs give the same bytes.
"""

from __future__ import annotations

import hashlib
import json
from decimal import Decimal

import pandas as pd

from tollcli import __version__
from tollcli.charging.recognition import GeoObjects
from tollcli.charging.tariffs import Tariff


def file_sha256(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _iso(ts) -> str:
    return pd.Timestamp(ts).tz_convert("UTC").strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _num(value):
    return None if value is None or pd.isna(value) else float(value)


def build_invoice(charges: pd.DataFrame, positions: pd.DataFrame, geo: GeoObjects, tariff: Tariff, *,
                  vehicle: str, vehicle_class: str, inputs: dict[str, str], parameters: dict, period) -> dict:  # fmt: skip
    """The invoice document (a dict of JSON-ready values)."""
    index = {gid: i for i, gid in enumerate(geo.ids)}
    by_passage = dict(iter(positions.groupby(["geoobject", "passage"], sort=False))) if len(positions) else {}
    lines, not_charged, total = [], [], Decimal(0)
    for row in charges.itertuples(index=False):
        i = index[row.geoobject]
        mine = by_passage[(row.geoobject, row.passage)]
        statuses = mine["verdict" if "verdict" in mine else "raim_status"].value_counts().sort_index()
        base = {
            "geoobject": row.geoobject, "name": geo.names[i], "road_class": geo.road_class[i], "hal_m": float(geo.hal_m[i]),
            "entry_utc": _iso(row.entry_utc), "exit_utc": _iso(row.exit_utc), "n_inside": int(row.n_inside),
            "n_valid": int(row.n_valid), "n_valid_independent": int(row.n_independent),
            "statuses": {str(k): int(v) for k, v in statuses.items()},
        }  # fmt: skip
        if not row.charged:
            not_charged.append(base)
            continue
        fee, band = tariff.fee(row.geoobject, geo.road_class[i], vehicle_class, pd.Timestamp(row.entry_utc).to_pydatetime())
        total += fee
        kept = mine[mine["independent"]]
        evidence = [
            {"epoch": int(e.epoch_row), "time_utc": _iso(e.time_utc), "raim_status": e.raim_status,
             "test_stat": _num(e.test_stat), "threshold": _num(e.threshold), "p_fa": _num(e.p_fa),
             "test_stat_source": e.test_stat_source}
            for e in kept.itertuples(index=False)
        ]  # fmt: skip
        lines.append({**base, "fee": str(fee), "band": band, "evidence": evidence})
    return {
        "tool": f"tollcli {__version__}",
        "vehicle": vehicle,
        "vehicle_class": vehicle_class,
        "currency": tariff.currency,
        "period": {"start_utc": _iso(period[0]), "end_utc": _iso(period[1])} if period else None,
        "inputs": inputs,
        "parameters": parameters,
        "lines": lines,
        "total": str(total.quantize(Decimal(1).scaleb(-tariff.minor_unit))),
        "not_charged": not_charged,
    }


def invoice_json(invoice: dict) -> str:
    return json.dumps(invoice, indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def invoice_csv(invoice: dict) -> str:
    """The invoice lines as CSV (one row per charged passage) with the total last."""
    cols = ["geoobject", "name", "road_class", "entry_utc", "exit_utc", "n_valid_independent", "band", "fee"]
    rows = [",".join(cols)]
    for line in invoice["lines"]:
        rows.append(",".join(json.dumps(line[c]) if isinstance(line[c], str) and "," in line[c] else str(line[c]) for c in cols))
    rows.append(",".join(["TOTAL", "", "", "", "", "", invoice["currency"], invoice["total"]]))
    return "\n".join(rows) + "\n"
