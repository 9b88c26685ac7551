"""Tariffs in TOML: fees per geo-object or road class, per vehicle class, with time-of-day bands.

Money is :class:`decimal.Decimal` from the file on: TOML numbers are parsed as
Decimal (``1.20`` stays exactly 1.20), never as binary floats. Example::

    currency = "EUR"
    minor_unit = 2                     # cents: fees are rounded half-up to 0.01
    timezone = "Europe/Paris"          # time bands are local times of this zone

    [road_class.motorway]              # default fee of every geo-object of that class
    car = 1.20
    truck = 3.40

    [geoobject."A9-1"]                 # a geo-object's own fee wins over its road class
    car = 0.80
    truck = 2.10

    [[band]]                           # the band holding the entry time scales the fee
    name = "peak"
    start = "07:00"                    # inclusive
    end = "09:30"                      # exclusive; a band may wrap past midnight
    days = ["mon", "tue", "wed", "thu", "fri"]   # optional, default every day
    factor = 1.5

Bands may not overlap (an entry time must have one factor); outside every band
the factor is 1.
"""

from __future__ import annotations

import datetime as dt
import tomllib
from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal, InvalidOperation
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from tollcli.errors import DataError, UsageError

DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")


@dataclass(frozen=True)
class Band:
    name: str
    start_min: int  # minutes after local midnight, inclusive
    end_min: int  # exclusive; < start_min when the band wraps past midnight
    days: frozenset[int]  # 0 = Monday
    factor: Decimal

    def holds(self, local: dt.datetime) -> bool:
        minute = local.hour * 60 + local.minute
        if self.start_min <= self.end_min:
            return local.weekday() in self.days and self.start_min <= minute < self.end_min
        if minute >= self.start_min:  # evening part of a band that wraps past midnight
            return local.weekday() in self.days
        return (local.weekday() - 1) % 7 in self.days and minute < self.end_min


@dataclass(frozen=True)
class Tariff:
    currency: str
    minor_unit: int
    timezone: str
    road_class: dict[str, dict[str, Decimal]]
    geoobject: dict[str, dict[str, Decimal]]
    bands: tuple[Band, ...]
    source: str = ""

    def fee(self, geoobject_id: str, road_class: str, vehicle_class: str, entry_utc: dt.datetime) -> tuple[Decimal, str]:
        """The fee for one charged geo-object and the band applied ('' for none)."""
        table = self.geoobject.get(geoobject_id) or self.road_class.get(road_class)
        if table is None:
            raise DataError(f"{self.source}: no fee for geo-object {geoobject_id!r} or its road class {road_class!r}")
        if vehicle_class not in table:
            raise DataError(f"{self.source}: no fee for vehicle class {vehicle_class!r} on {geoobject_id!r} ({road_class})")
        if entry_utc.tzinfo is None:
            raise ValueError("entry time must be timezone-aware (UTC)")
        local = entry_utc.astimezone(ZoneInfo(self.timezone))
        band = next((b for b in self.bands if b.holds(local)), None)
        factor = band.factor if band else Decimal(1)
        quantum = Decimal(1).scaleb(-self.minor_unit)
        return (table[vehicle_class] * factor).quantize(quantum, rounding=ROUND_HALF_UP), band.name if band else ""


def _money(value, where: str) -> Decimal:
    if isinstance(value, bool) or not isinstance(value, (int, Decimal, str)):
        raise DataError(f"{where}: a fee must be a number, got {value!r}")
    try:
        amount = Decimal(value)
    except InvalidOperation:
        raise DataError(f"{where}: not a number: {value!r}") from None
    if not amount.is_finite() or amount < 0:
        raise DataError(f"{where}: a fee must be a finite amount ≥ 0, got {value}")
    return amount


def _minutes(text, where: str) -> int:
    try:
        t = dt.time.fromisoformat(str(text))
    except ValueError:
        raise DataError(f"{where}: time {text!r} is not HH:MM") from None
    return t.hour * 60 + t.minute


def _fee_tables(section, name: str, path: str) -> dict[str, dict[str, Decimal]]:
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise DataError(f"{path}: [{name}] must be a table")
    out = {}
    for key, fees in section.items():
        if not isinstance(fees, dict) or not fees:
            raise DataError(f"{path}: [{name}.{key}] must map vehicle classes to fees")
        out[str(key)] = {str(vc): _money(v, f"{path}: [{name}.{key}] {vc}") for vc, v in fees.items()}
    return out


def _bands(items, path: str) -> tuple[Band, ...]:
    if items is None:
        return ()
    if not isinstance(items, list):
        raise DataError(f"{path}: [[band]] must be an array of tables")
    bands = []
    for i, item in enumerate(items):
        where = f"{path}: band {item.get('name', i + 1) if isinstance(item, dict) else i + 1}"
        if not isinstance(item, dict):
            raise DataError(f"{where}: must be a table")
        for key in ("start", "end", "factor"):
            if key not in item:
                raise DataError(f"{where}: missing {key}")
        days = item.get("days", list(DAYS))
        if not isinstance(days, list) or any(str(d).lower()[:3] not in DAYS for d in days):
            raise DataError(f"{where}: days must be a list of mon … sun")
        start, end = _minutes(item["start"], where), _minutes(item["end"], where)
        if start == end:
            raise DataError(f"{where}: start and end are equal")
        bands.append(Band(str(item.get("name", f"band{i + 1}")), start, end,
                          frozenset(DAYS.index(str(d).lower()[:3]) for d in days), _money(item["factor"], f"{where} factor")))  # fmt: skip
    # no two bands may hold the same minute of the week
    week = {}
    for band in bands:
        for day in band.days:
            span = range(band.start_min, band.end_min) if band.start_min < band.end_min else list(range(band.start_min, 1440)) + [1440 + m for m in range(band.end_min)]
            for minute in span:
                slot = (day * 1440 + minute) % (7 * 1440)
                if slot in week:
                    raise DataError(f"{path}: bands {week[slot]!r} and {band.name!r} overlap")
                week[slot] = band.name
    return tuple(bands)


def load_tariff(path: str) -> Tariff:
    """Read and validate a tariff file (DataError naming the file and the key on problems)."""
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh, parse_float=Decimal)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a TOML tariff ({exc})") from None
    currency = doc.get("currency")
    if not isinstance(currency, str) or len(currency) != 3 or not currency.isalpha():
        raise DataError(f"{path}: currency must be an ISO 4217 code such as \"EUR\"")
    minor = doc.get("minor_unit", 2)
    if not isinstance(minor, int) or isinstance(minor, bool) or not 0 <= minor <= 4:
        raise DataError(f"{path}: minor_unit must be an integer 0…4")
    timezone = doc.get("timezone", "UTC")
    try:
        ZoneInfo(str(timezone))
    except (ZoneInfoNotFoundError, ValueError):
        raise DataError(f"{path}: unknown timezone {timezone!r}") from None
    road_class = _fee_tables(doc.get("road_class"), "road_class", path)
    geoobject = _fee_tables(doc.get("geoobject"), "geoobject", path)
    if not road_class and not geoobject:
        raise DataError(f"{path}: no fees: give [road_class.<name>] or [geoobject.<id>] tables")
    return Tariff(currency.upper(), minor, str(timezone), road_class, geoobject, _bands(doc.get("band"), path), path)
