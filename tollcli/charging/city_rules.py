"""A city tariff's rules over a day's charges: the calendar, a zone charged once a day, the single-charge rule and
the daily cap — applied in that order, per vehicle and local day, each saying what it changed.

Pure functions of the set of charges: the same crossings in any order, or split over several logs of the day (``batch``
joins them), give the same total. Money is ``Decimal``.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from decimal import Decimal

from tollcli.charging.city_tariff import CityTariff


@dataclass(frozen=True)
class Charge:
    """One priced event before the rules: a gantry crossing or a zone presence in charging hours."""

    kind: str  # "crossing" or "zone"
    obj: str  # gantry or zone id
    time_utc: dt.datetime  # tz-aware
    amount: Decimal  # the rate's (crossing) or the zone charge's amount for the vehicle
    rate: str  # the rate's or zone charge's name
    direction: str = ""  # crossings: left_to_right / right_to_left
    calendar: bool = True  # whether the calendar's free days apply
    key: str = ""  # the line's id in its invoice (log + index), kept through the rules


def _fmt(amount: Decimal, tariff: CityTariff) -> str:
    return f"{amount.quantize(Decimal(1).scaleb(-tariff.minor_unit))}"


def apply_rules(charges: list[Charge], tariff: CityTariff) -> tuple[dict[str, Decimal], list[dict], list[dict], Decimal]:
    """The rules over ``charges``: (what each charge pays after the per-charge rules, by key; the rules applied, in order,
    each with its day, what it said and its change; each day's sums; the total)."""
    zone = tariff.zone
    ordered = sorted(charges, key=lambda c: (c.time_utc, c.kind, c.obj, c.key))
    by_day: dict[dt.date, list[Charge]] = {}
    for c in ordered:
        by_day.setdefault(c.time_utc.astimezone(zone).date(), []).append(c)
    paid: dict[str, Decimal] = {}
    rules: list[dict] = []
    days: list[dict] = []
    cur = tariff.currency
    for day in sorted(by_day):
        items = by_day[day]
        pay = {c.key: c.amount for c in items}
        before = sum(pay.values(), Decimal(0))
        free = tariff.calendar.free_reason(day)
        freed = [c for c in items if free and c.calendar and pay[c.key] > 0]
        if freed:
            change = -sum((pay[c.key] for c in freed), Decimal(0))
            for c in freed:
                pay[c.key] = Decimal(0)
            rules.append({"rule": "free_day", "date": day.isoformat(), "change": _fmt(change, tariff),
                          "said": f"{day.isoformat()}: {free}: {len(freed)} charge{'s' * (len(freed) > 1)} free ({_fmt(change, tariff)} {cur})"})  # fmt: skip
        _zone_once(items, pay, day, rules, tariff)
        if tariff.single_charge_min is not None:
            _single_charge([c for c in items if c.kind == "crossing" and pay[c.key] > 0], pay, day, rules, tariff)
        total = sum(pay.values(), Decimal(0))
        capped = total
        if tariff.daily_cap is not None and total > tariff.daily_cap:
            capped = tariff.daily_cap
            rules.append({"rule": "daily_cap", "date": day.isoformat(), "change": _fmt(capped - total, tariff),
                          "said": f"{day.isoformat()}: daily cap {_fmt(tariff.daily_cap, tariff)} {cur} reached: {_fmt(capped - total, tariff)} {cur}"})  # fmt: skip
        paid.update(pay)
        days.append({"date": day.isoformat(), "charges": len(items), "before_rules": _fmt(before, tariff),
                     "total": _fmt(capped, tariff), **({"free": free} if free else {})})  # fmt: skip
    total = sum((Decimal(d["total"]) for d in days), Decimal(0))
    return paid, rules, days, total


def _zone_once(items: list[Charge], pay: dict, day: dt.date, rules: list[dict], tariff: CityTariff) -> None:
    """A zone charge is paid once a day, however often the vehicle is present."""
    seen: dict[tuple[str, str], list[Charge]] = {}
    for c in items:
        if c.kind == "zone" and pay[c.key] > 0:
            seen.setdefault((c.obj, c.rate), []).append(c)
    for (obj, rate), group in sorted(seen.items()):
        if len(group) < 2:
            continue
        keep = max(group, key=lambda c: (pay[c.key], -group.index(c)))
        change = -sum((pay[c.key] for c in group if c is not keep), Decimal(0))
        for c in group:
            if c is not keep:
                pay[c.key] = Decimal(0)
        rules.append({"rule": "zone_once_a_day", "date": day.isoformat(), "change": _fmt(change, tariff),
                      "said": f"{day.isoformat()}: zone {obj}: {len(group)} presences → charged once, {_fmt(pay[keep.key], tariff)} {tariff.currency}"})  # fmt: skip


def _single_charge(crossings: list[Charge], pay: dict, day: dt.date, rules: list[dict], tariff: CityTariff) -> None:
    """Passages within the window of a window's first are charged once, at the highest amount among them."""
    window = dt.timedelta(minutes=tariff.single_charge_min)
    zone = tariff.zone
    i = 0
    while i < len(crossings):
        start = crossings[i].time_utc
        group = [c for c in crossings[i:] if c.time_utc < start + window]
        i += len(group)
        if len(group) < 2:
            continue
        top = max(pay[c.key] for c in group)
        keep = next(c for c in group if pay[c.key] == top)  # the first with the highest amount
        change = -sum((pay[c.key] for c in group if c is not keep), Decimal(0))
        for c in group:
            if c is not keep:
                pay[c.key] = Decimal(0)
        first, last = group[0].time_utc.astimezone(zone), group[-1].time_utc.astimezone(zone)
        rules.append({"rule": "single_charge", "date": day.isoformat(), "change": _fmt(change, tariff),
                      "said": f"single-charge: {len(group)} passages {first:%H:%M}–{last:%H:%M} → {_fmt(top, tariff)} {tariff.currency}"})  # fmt: skip


def invoice_charges(invoice: dict, tariff: CityTariff) -> list[Charge]:
    """The charges a city invoice's lines stand for, before the rules (``batch`` and ``audit`` join a vehicle's logs of one
    day with them)."""
    calendar = {c.name: c.calendar for c in tariff.zone_charges}
    inputs = invoice.get("inputs") or {}
    log = inputs.get("log_sha256") or inputs.get("log", "")
    out = []
    for i, line in enumerate(invoice.get("lines") or []):
        when = dt.datetime.fromisoformat(line["time_utc"].replace("Z", "+00:00"))
        out.append(Charge(line["kind"], line["geoobject"], when, Decimal(line["fee"]), line["rate"], line.get("direction", ""),
                          calendar.get(line["rate"], True) if line["kind"] == "zone" else True, f"{log}#{i}"))  # fmt: skip
    return out
