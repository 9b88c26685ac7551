"""City invoices against a truth trajectory: the gantry crossings and zone presences really driven, priced and ruled as
the tariff says, against what the invoices charged — missed and false crossings, each rule's change and each day's
total on both sides, the under- and overcharge.

The truth's crossings are where its straight path between consecutive points crosses a gantry's line (in a direction
the gantry charges); its zone presences are its points inside a zone (runs at most ``PRESENCE_GAP_S`` apart), charged at
the first point in a zone charge's hours. An invoice's crossing matches a true one of the same gantry and direction
within :data:`MATCH_S`.
"""

from __future__ import annotations

import datetime as dt
from decimal import Decimal

import numpy as np
import pandas as pd
import shapely

from tollcli.charging.city_evidence import PRESENCE_GAP_S, _runs, path_crossings
from tollcli.charging.city_rules import Charge, apply_rules, invoice_charges
from tollcli.charging.city_tariff import CityTariff
from tollcli.geoobjects.city import CityNetwork

#: an invoice's crossing is the true one of its gantry and direction within this time, s
MATCH_S = 60.0


def truth_charges(net: CityNetwork, tariff: CityTariff, truth: pd.DataFrame, vehicle_class: str, attrs: dict) -> list[Charge]:
    """The charges the truth trajectory (``time_utc``, ``lat_deg``, ``lon_deg``) owes under the tariff, before the rules."""
    from tollcli.charging.recognition import utc_seconds
    from tollcli.spatial import wgs84_to

    truth = truth.dropna(subset=["time_utc"]).sort_values("time_utc", kind="stable")
    t = utc_seconds(truth["time_utc"])
    x, y = (np.asarray(v, float) for v in wgs84_to(net.crs).transform(truth["lon_deg"].to_numpy(float), truth["lat_deg"].to_numpy(float)))
    out = []
    if tariff.rates:
        for p in path_crossings(net, t, x, y).itertuples(index=False):
            gid = net.ids[p.obj]
            if net.direction[p.obj] not in ("both", p.direction):
                continue
            priced = tariff.crossing_price((p.t_s,), gid, p.direction, vehicle_class, attrs)
            if priced is None or priced[1] is None:
                continue
            out.append(Charge("crossing", gid, dt.datetime.fromtimestamp(p.t_s, dt.UTC), priced[1], priced[0].name, p.direction, True,
                              f"truth#{len(out)}"))  # fmt: skip
    zone = tariff.zone
    for k in np.flatnonzero(net.kinds == "zone"):
        inside = np.flatnonzero(shapely.contains_xy(net.geoms[k], x, y))
        for lo, hi in _runs(t[inside], PRESENCE_GAP_S):
            times = t[inside[lo:hi]]
            for charge in tariff.zone_charges:
                if not charge.applies_to(attrs):
                    continue
                at = next((s for s in times if charge.holds(dt.datetime.fromtimestamp(s, dt.UTC).astimezone(zone), net.ids[k])), None)
                amount = charge.price(vehicle_class)
                if at is None or amount is None:
                    continue
                out.append(Charge("zone", net.ids[k], dt.datetime.fromtimestamp(at, dt.UTC), amount, charge.name, "", charge.calendar,
                                  f"truth#{len(out)}"))  # fmt: skip
    return out


def city_audit(invoices: list[dict], net: CityNetwork, tariff: CityTariff, truth: pd.DataFrame, vehicle_class: str,
               attrs: dict) -> dict:  # fmt: skip
    """The audit report of one vehicle's city invoices (one or several logs) against its truth trajectory."""
    true = truth_charges(net, tariff, truth, vehicle_class, attrs)
    charged = [c for inv in invoices for c in invoice_charges(inv, tariff)]
    missed, false = _unmatched(true, charged), _unmatched(charged, true)
    _, true_rules, true_days, true_total = apply_rules(true, tariff)
    _, rules, days, total = apply_rules(charged, tariff)
    by_rule: dict[str, dict[str, Decimal]] = {}
    for side, applied in (("truth", true_rules), ("invoices", rules)):
        for r in applied:
            by_rule.setdefault(r["rule"], {"truth": Decimal(0), "invoices": Decimal(0)})[side] += Decimal(r["change"])
    day_of = {d["date"]: d for d in days}
    true_day_of = {d["date"]: d for d in true_days}
    per_day = [{"date": d, "truth_total": true_day_of.get(d, {}).get("total", "0"), "invoiced_total": day_of.get(d, {}).get("total", "0")}
               for d in sorted(set(day_of) | set(true_day_of))]  # fmt: skip
    return {
        "crossings_driven": sum(c.kind == "crossing" for c in true), "crossings_charged": sum(c.kind == "crossing" for c in charged),
        "zone_presences_driven": sum(c.kind == "zone" for c in true), "zone_presences_charged": sum(c.kind == "zone" for c in charged),
        "missed": [_said(c) for c in missed], "false": [_said(c) for c in false],
        "rules": {k: {s: str(v) for s, v in sides.items()} for k, sides in sorted(by_rule.items())},
        "truth_rules": true_rules, "days": per_day, "currency": tariff.currency,
        "truth_total": str(true_total), "invoiced_total": str(total),
        "undercharge": str(max(true_total - total, Decimal(0))), "overcharge": str(max(total - true_total, Decimal(0))),
    }  # fmt: skip


def _unmatched(these: list[Charge], others: list[Charge]) -> list[Charge]:
    """The charges of ``these`` no charge of ``others`` stands for (the same kind, object and direction; a crossing within
    :data:`MATCH_S`, a zone presence on the same day), each matched at most once."""
    used: set[int] = set()
    out = []
    for c in sorted(these, key=lambda c: (c.time_utc, c.obj)):
        match = None
        for j, o in enumerate(others):
            if j in used or o.kind != c.kind or o.obj != c.obj or o.direction != c.direction or o.rate != c.rate:
                continue
            close = abs((o.time_utc - c.time_utc).total_seconds()) <= MATCH_S if c.kind == "crossing" else o.time_utc.date() == c.time_utc.date()
            if close:
                match = j
                break
        if match is None:
            out.append(c)
        else:
            used.add(match)
    return out


def _said(c: Charge) -> dict:
    return {"kind": c.kind, "geoobject": c.obj, "direction": c.direction, "time_utc": c.time_utc.isoformat().replace("+00:00", "Z"),
            "rate": c.rate, "amount": str(c.amount)}  # fmt: skip


def driven_city_objects(net: CityNetwork, truth: pd.DataFrame) -> list[str]:
    """The gantries a truth trajectory crosses (either way) and the zones it enters, sorted (the simulator's truth)."""
    from tollcli.charging.recognition import utc_seconds
    from tollcli.spatial import wgs84_to

    truth = truth.dropna(subset=["time_utc"]).sort_values("time_utc", kind="stable")
    x, y = (np.asarray(v, float) for v in wgs84_to(net.crs).transform(truth["lon_deg"].to_numpy(float), truth["lat_deg"].to_numpy(float)))
    crossed = {net.ids[k] for k in path_crossings(net, utc_seconds(truth["time_utc"]), x, y)["obj"]}
    entered = {net.ids[k] for k in np.flatnonzero(net.kinds == "zone") if shapely.contains_xy(net.geoms[k], x, y).any()}
    return sorted(crossed | entered)
