"""``batch`` under a city tariff: a vehicle's logs of one day charged as one day — the single-charge window and the daily
cap apply across the logs (a window or a cap never restarts at a file boundary), written to ``OUTDIR/city-days.json``."""

from __future__ import annotations

import json
import os
from decimal import Decimal

from tollcli.charging.city_rules import apply_rules, invoice_charges
from tollcli.charging.city_tariff import load_city_tariff
from tollcli.io.writers import write_text_atomic


def settle_city_days(outcomes: list[dict], outdir: str, tariff_path: str) -> dict:
    """Per vehicle: the rules over all its logs' charges, by local day; returns the totals per currency and writes
    ``city-days.json`` (vehicle → days, rules applied, total)."""
    tariff = load_city_tariff(tariff_path)
    charges: dict[str, list] = {}
    for o in sorted(outcomes, key=lambda o: o["log"]):
        if o["status"] not in ("done", "skipped"):
            continue
        try:
            with open(os.path.join(outdir, o["invoice"]), encoding="utf-8") as fh:
                invoice = json.load(fh)
        except (OSError, ValueError):
            continue
        charges.setdefault(str(o["vehicle"]), []).extend(invoice_charges(invoice, tariff))
    vehicles = {}
    total = Decimal(0)
    for vehicle in sorted(charges):
        _, rules, days, vehicle_total = apply_rules(charges[vehicle], tariff)
        vehicles[vehicle] = {"days": days, "rules": rules, "total": str(vehicle_total)}
        total += vehicle_total
    write_text_atomic(os.path.join(outdir, "city-days.json"),
                      json.dumps({"currency": tariff.currency, "vehicles": vehicles}, indent=1, sort_keys=True) + "\n")  # fmt: skip
    return {tariff.currency: str(total)}
