"""Tariffs in TOML: flat fees per geo-object or road class and vehicle class, or per-km tables; time-of-day bands.

``docs/tariffs.md`` documents the format with complete examples. Per-km tables (rates per km and per
passage by vehicle attributes, valid from a date) are read and priced by ``rate_tables.py``; this module
reads the file, the flat fees and the bands. A flat tariff looks like this::

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

Money is :class:`decimal.Decimal` from the file on: TOML numbers are parsed as
Decimal (``1.20`` stays exactly 1.20), never as binary floats.

A typo must never change a fee silently: an unknown key, day, vehicle class or currency minor unit
is an error naming the key and its line. The vehicle classes a fee table may name are the usual ones
(:data:`KNOWN_VEHICLE_CLASSES`: car, van, truck, bus, …), or exactly those the tariff declares with
``vehicle_classes = ["car", "camper", …]``. A fee keeps every digit the file gives until
the one rounding (half-up, to the currency's minor unit); fees are below 10^12.
"""

from __future__ import annotations

import datetime as dt
import math
import re
import tomllib
from dataclasses import dataclass, field
from decimal import ROUND_HALF_UP, Decimal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from tollcli.charging.money import at_least_minor_unit, exact, exact_fee, line_of
from tollcli.charging.money import money as _money
from tollcli.charging.money import where as _where
from tollcli.charging.rate_tables import (
    VEHICLE_CLASS,
    Price,
    RateTable,
    chosen_rates,
    parse_tables,
    parse_vehicle,
    table_in_force,
)
from tollcli.geoobjects.road_sections import road_of
from tollcli.errors import DataError, UsageError

DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
DAY_NAMES = ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday")
TOP_KEYS = ("currency", "minor_unit", "timezone", "road_class", "geoobject", "band", "vehicle", "table", "length_km",
            "vehicle_classes")
#: the vehicle classes a flat tariff may price without declaring them (``vehicle_classes = [...]`` declares others):
#: a key outside them is a typo (``vna = 1.40`` priced no van) and an error naming its line
KNOWN_VEHICLE_CLASSES = ("car", "van", "truck", "bus", "coach", "motorcycle", "lorry", "hgv", "lgv", "trailer", "caravan",
                         "minibus", "taxi", "tractor", "class1", "class2", "class3", "class4", "class5")
BAND_KEYS = ("name", "start", "end", "days", "factor")
MAX_FACTOR = Decimal(100)
#: ISO 4217 currencies whose minor unit is not 2 (the others have cents)
MINOR_UNITS = {
    **dict.fromkeys(("BIF", "CLP", "DJF", "GNF", "ISK", "JPY", "KMF", "KRW", "PYG", "RWF", "UGX", "UYI", "VND", "VUV",
                     "XAF", "XOF", "XPF"), 0),
    **dict.fromkeys(("BHD", "IQD", "JOD", "KWD", "LYD", "OMR", "TND"), 3),
    **dict.fromkeys(("CLF", "UYW"), 4),
}  # fmt: skip


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
    #: per-km tables (rate_tables.py), in force one after the other; empty for a tariff of flat fees
    tables: tuple[RateTable, ...] = ()
    #: [vehicle]: attribute → the values it may take (per-km tables)
    vehicle: dict[str, frozenset[str]] = field(default_factory=dict)
    #: [length_km]: geo-object id → its tariff length, km (wins over the geo-object's own length)
    length_km: dict[str, Decimal] = field(default_factory=dict)

    def vehicle_classes(self) -> list[str]:
        """The vehicle classes the tariff prices (empty: per-km tables that do not filter on the class)."""
        if self.tables:
            return sorted(self.vehicle.get(VEHICLE_CLASS, ()))
        return sorted({vc for table in (*self.road_class.values(), *self.geoobject.values()) for vc in table})

    def check_against(self, geo_ids, road_classes, geo_source: str) -> None:
        """DataError when the per-km tables name a geo-object or road class the geo-object file does not have:
        a misspelt id or class would otherwise leave its row unused and change fees silently."""
        if not self.length_km and not any(rate.geoobjects or rate.road_classes for table in self.tables for rate in table.rates):
            return  # nothing named: nothing to look up in a network of any size
        ids, classes = set(map(str, geo_ids)), set(map(str, road_classes))
        ids |= {road_of(i) for i in ids}  # a road cut into sections (ID/1, ID/2…) is named by its id
        unknown = sorted(set(self.length_km) - ids)
        if unknown:
            raise DataError(f"{self.source}: [length_km] names geo-object {unknown[0]!r}, which {geo_source} does not have "
                            f"(a misspelt id would leave its length unused)")  # fmt: skip
        for table in self.tables:
            for rate in table.rates:
                for what, named, present in (("geo-object", rate.geoobjects, ids), ("road class", rate.road_classes, classes)):
                    missing = sorted((named or set()) - present)
                    if missing:
                        where = f"{self.source}:{rate.line}" if rate.line else self.source
                        raise DataError(f"{where}: the rate names {what} {missing[0]!r}, which {geo_source} does not "
                                        f"have (a misspelt {what} would leave the rate unused)")  # fmt: skip

    def _band(self, entry_utc: dt.datetime) -> Band | None:
        if entry_utc.tzinfo is None:
            raise ValueError("entry time must be timezone-aware (UTC)")
        local = entry_utc.astimezone(ZoneInfo(self.timezone))
        return next((b for b in self.bands if b.holds(local)), None)

    def fee(self, geoobject_id: str, road_class: str, vehicle_class: str, entry_utc: dt.datetime) -> tuple[Decimal, str]:
        """The flat fee for one charged geo-object and the band applied ('' for none)."""
        if self.tables:
            raise DataError(f"{self.source}: a per-km tariff prices a passage by its length: use price()")
        table = self.geoobject.get(geoobject_id) or self.geoobject.get(road_of(geoobject_id)) or self.road_class.get(road_class)
        if table is None:
            raise DataError(f"{self.source}: no fee for geo-object {geoobject_id!r} or its road class {road_class!r}")
        if vehicle_class not in table:
            raise DataError(f"{self.source}: no fee for vehicle class {vehicle_class!r} on {geoobject_id!r} ({road_class})")
        band = self._band(entry_utc)
        factor = band.factor if band else Decimal(1)
        return exact_fee(table[vehicle_class], factor, self.minor_unit), band.name if band else ""

    def price(self, geoobject_id: str, road_class: str, length_m: float | None, vehicle: dict[str, str],
              entry_utc: dt.datetime) -> Price:  # fmt: skip
        """What one passage costs: flat fee, or per-km rates of the table in force at its entry.

        ``length_m``: the geo-object's section length (ground metres; None or NaN when it has none);
        ``vehicle``: its attributes, with ``vehicle_class``.
        """
        if not self.tables:
            return Price(*self.fee(geoobject_id, road_class, vehicle[VEHICLE_CLASS], entry_utc))
        table = table_in_force(self.tables, entry_utc, self.source)
        rates = chosen_rates(table, geoobject_id, road_class, vehicle, self.source)
        per_km = sum((r.per_km for r in rates.values()), Decimal(0))
        per_passage = sum((r.per_passage for r in rates.values()), Decimal(0))
        length_km = self.section_km(geoobject_id, length_m) if per_km else None
        amount = exact(lambda: per_passage + per_km * (length_km or 0))
        band = self._band(entry_utc)
        fee = exact_fee(amount, band.factor if band else Decimal(1), self.minor_unit)
        components = {c: {"per_km": str(r.per_km), "per_passage": str(r.per_passage), "line": r.line} for c, r in rates.items()}
        return Price(fee, band.name if band else "", table.name, length_km, per_km, per_passage, components)

    def section_km(self, geoobject_id: str, length_m: float | None) -> Decimal:
        """The length charged for a geo-object, km: the tariff's ``[length_km]``, else its length in whole metres."""
        if geoobject_id in self.length_km:
            return self.length_km[geoobject_id]
        if length_m is None or not math.isfinite(length_m) or length_m <= 0:
            raise DataError(f"{self.source}: geo-object {geoobject_id!r} has no length for a per-km rate: build it with "
                            f"'tollcli geoobjects build' (section_length_m) or give it under [length_km]")  # fmt: skip
        return Decimal(repr(float(length_m))).quantize(Decimal(1), rounding=ROUND_HALF_UP).scaleb(-3)  # whole metres


def _minutes(text, where: str) -> int:
    try:
        t = dt.time.fromisoformat(str(text))
    except ValueError:
        raise DataError(f"{where}: time {text!r} is not HH:MM") from None
    return t.hour * 60 + t.minute


def _fee_tables(section, name: str, path: str, minor_unit: int, text: str = "",
                classes: tuple[str, ...] = KNOWN_VEHICLE_CLASSES) -> dict[str, dict[str, Decimal]]:  # fmt: skip
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise DataError(f"{path}: [{name}] must be a table")
    out = {}
    for key, fees in section.items():
        if not isinstance(fees, dict) or not fees:
            raise DataError(f"{path}: [{name}.{key}] must map vehicle classes to fees")
        for vc in fees:
            if str(vc) not in classes:
                import difflib

                near = difflib.get_close_matches(str(vc), classes, n=1)
                header = line_of(text, f"{name}.{key}") or line_of(text, f'{name}."{key}"')
                raise DataError(f"{_where(path, text, str(vc), header)}: [{name}.{key}] {vc}: unknown vehicle class"
                                + (f" (did you mean {near[0]}?)" if near else "")
                                + "; the classes are " + ", ".join(classes[:6]) + (", …" if len(classes) > 6 else "")
                                + " — declare others with vehicle_classes = [...]")  # fmt: skip
        out[str(key)] = {str(vc): at_least_minor_unit(_money(v, f"{path}: [{name}.{key}] {vc}"), minor_unit, f"{path}: [{name}.{key}] {vc}")
                         for vc, v in fees.items()}  # fmt: skip
    return out


def _declared_classes(value, path: str, text: str) -> tuple[str, ...]:
    """The vehicle classes a tariff declares (``vehicle_classes = [...]``), else :data:`KNOWN_VEHICLE_CLASSES`."""
    if value is None:
        return KNOWN_VEHICLE_CLASSES
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v.strip() for v in value):
        raise DataError(f"{_where(path, text, 'vehicle_classes')}: vehicle_classes must be a list of class names")
    return tuple(str(v) for v in value)


def _day(value) -> int | None:
    """0 … 6 for mon … sun (three letters or the whole English name, any case); None for anything else."""
    text = str(value).strip().lower()
    if text in DAYS:
        return DAYS.index(text)
    return DAY_NAMES.index(text) if text in DAY_NAMES else None


def _bands(items, path: str, text: str = "") -> tuple[Band, ...]:
    if items is None:
        return ()
    if not isinstance(items, list):
        raise DataError(f"{path}: [[band]] must be an array of tables")
    bands = []
    for i, item in enumerate(items):
        header = _nth_band_line(text, i)
        label = item.get("name", i + 1) if isinstance(item, dict) else i + 1
        where = f"{path}:{header}: band {label}" if header else f"{path}: band {label}"
        if not isinstance(item, dict):
            raise DataError(f"{where}: must be a table")
        for key in item:
            if key not in BAND_KEYS:
                raise DataError(f"{_where(path, text, key, header)}: band {label}: unknown key {key!r} "
                                f"(a band has {', '.join(BAND_KEYS)})")  # fmt: skip
        for key in ("start", "end", "factor"):
            if key not in item:
                raise DataError(f"{where}: missing {key}")
        days = item.get("days", list(DAYS))
        if not isinstance(days, list) or not days or any(_day(d) is None for d in days):
            bad = next((d for d in days if _day(d) is None), None) if isinstance(days, list) else days
            raise DataError(f"{_where(path, text, 'days', header)}: band {label}: days must be a list of "
                            f"mon … sun (or monday … sunday), got {bad!r}")  # fmt: skip
        start, end = _minutes(item["start"], where), _minutes(item["end"], where)
        if start == end:
            raise DataError(f"{where}: start and end are equal")
        bands.append(Band(str(item.get("name", f"band{i + 1}")), start, end,
                          frozenset(_day(d) for d in days), _money(item["factor"], f"{where} factor", MAX_FACTOR)))  # fmt: skip
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


def _nth_band_line(text: str, index: int) -> int:
    """The line of the ``index``-th ``[[band]]`` header (0 when not found)."""
    return nth_table_line(text, "band", index)


def nth_table_line(text: str, name: str, index: int) -> int:
    """The line of the ``index``-th ``[[name]]`` header of a TOML text (0 when not found)."""
    headers = [n for n, line in enumerate(text.splitlines(), 1) if re.match(rf"^\s*\[\[\s*{re.escape(name)}\s*\]\]", line)]
    return headers[index] if index < len(headers) else 0


def load_tariff(path: str) -> Tariff:
    """Read and validate a tariff file (DataError naming the file and the key on problems)."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
        text = raw.decode("utf-8-sig")  # (a byte-order mark, as some editors write, is no statement)
        doc = tomllib.loads(text, parse_float=Decimal)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a tariff file") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a TOML tariff ({exc})") from None
    for key in doc:
        if key not in TOP_KEYS:
            raise DataError(f"{_where(path, text, key)}: unknown key {key!r} (a tariff has {', '.join(TOP_KEYS)})")
    currency = doc.get("currency")
    if not isinstance(currency, str) or len(currency) != 3 or not currency.isalpha():
        raise DataError(f"{path}: currency must be an ISO 4217 code such as \"EUR\"")
    minor = doc.get("minor_unit", 2)
    if not isinstance(minor, int) or isinstance(minor, bool) or not 0 <= minor <= 4:
        raise DataError(f"{_where(path, text, 'minor_unit')}: minor_unit must be an integer 0…4")
    iso_minor = MINOR_UNITS.get(currency.upper(), 2)
    if minor != iso_minor:
        raise DataError(f"{_where(path, text, 'minor_unit')}: minor_unit {minor} does not fit {currency.upper()}, "
                        f"whose minor unit is {iso_minor} (ISO 4217)")  # fmt: skip
    timezone = doc.get("timezone", "UTC")
    try:
        ZoneInfo(str(timezone))
    except (ZoneInfoNotFoundError, ValueError):
        raise DataError(f"{path}: unknown timezone {timezone!r}") from None
    classes = _declared_classes(doc.get("vehicle_classes"), path, text)
    road_class = _fee_tables(doc.get("road_class"), "road_class", path, minor, text, classes)
    geoobject = _fee_tables(doc.get("geoobject"), "geoobject", path, minor, text, classes)
    bands = _bands(doc.get("band"), path, text)
    if "table" in doc:
        if road_class or geoobject:
            raise DataError(f"{_where(path, text, 'road_class' if road_class else 'geoobject')}: give fees either as "
                            f"[road_class]/[geoobject] tables or as [[table]] rates, not both")  # fmt: skip
        if "vehicle_classes" in doc:
            raise DataError(f"{_where(path, text, 'vehicle_classes')}: vehicle_classes belongs to a flat tariff; a tariff of "
                            f"[[table]] rates declares its classes in [vehicle]")  # fmt: skip
        vehicle = parse_vehicle(doc.get("vehicle"), path, text)
        tables = parse_tables(doc["table"], vehicle, ZoneInfo(str(timezone)), path, text)
        lengths = doc.get("length_km") or {}
        if not isinstance(lengths, dict):
            raise DataError(f"{_where(path, text, 'length_km')}: [length_km] must map geo-object ids to km")
        length_km = {str(k): _money(v, f"{_where(path, text, str(k), line_of(text, 'length_km'))}: length_km {k}")
                     for k, v in lengths.items()}  # fmt: skip
        return Tariff(currency.upper(), minor, str(timezone), {}, {}, bands, path, tables, vehicle, length_km)
    for key in ("vehicle", "length_km"):  # (and vehicle_classes: a flat tariff's; a table's are its [vehicle] attributes)
        if key in doc:
            raise DataError(f"{_where(path, text, key)}: [{key}] belongs to a tariff of [[table]] rates")
    if not road_class and not geoobject:
        raise DataError(f"{path}: no fees: give [road_class.<name>] or [geoobject.<id>] tables, or [[table]] rates")
    return Tariff(currency.upper(), minor, str(timezone), road_class, geoobject, bands, path)
