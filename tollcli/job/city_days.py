"""``batch`` under a city tariff: a vehicle's logs of one day charged as one day — the single-charge window and the daily
cap apply across the logs (a window or a cap never restarts at a file boundary), written to ``OUTDIR/city-days.json``."""

from __future__ import annotations

import json
import os
from decimal import Decimal

from tollcli.charging.city_rules import apply_rules, invoice_charges
from tollcli.charging.city_tariff import load_city_tariff
from tollcli.io.writers import write_text_atomic


def check_city_inputs(geo: str, tariff_path: str, settings, fleet: bool) -> None:
    """What every log of a city batch shares, checked once: the tariff, the settings (the vehicle class unless a fleet
    file gives each its own) and the gantries and zones."""
    from tollcli.geoobjects.city import load_city_network
    from tollcli.job.city_charge import check_city_settings
    from tollcli.job.pipeline import check_settings

    tariff = load_city_tariff(tariff_path)
    check_settings(settings)
    if not fleet:
        check_city_settings(settings, tariff)
    net = load_city_network(geo)
    tariff.check_against(net.ids, net.kinds, geo)


def settle_city_days(summary: dict, outcomes: list[dict], outdir: str, tariff_path: str) -> None:
    """Under a city tariff (nothing otherwise): per vehicle, the rules over all its logs' charges by local day, written
    to ``city-days.json`` (vehicle → days, rules applied, total); the summary's ``totals`` become those, the invoices'
    own sum ``invoice_totals``."""
    from tollcli.charging.city_tariff import is_city_tariff

    if not is_city_tariff(tariff_path):
        return
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
    summary.update(invoice_totals=summary["totals"], totals={tariff.currency: str(total)}, city_days="city-days.json")
