"""Per-km toll tables: rates per km of section and per passage, by vehicle category, valid from a date.

The way truck tolls are published (Germany, Austria, Czechia, Poland, Hungary,
Belgium): a table in force from a date gives, for each combination of vehicle
attributes (weight class, axles, Euro emission class, CO₂ class…), a rate per km
of each tolled section, often as a sum of parts (infrastructure, air pollution,
noise, CO₂). ``docs/tariffs.md`` documents the file format with a complete example.

A rate row applies to a passage when its selector (``geoobject``, ``road_class``, or
none: every geo-object) holds the passage's geo-object and each of its attribute
filters holds the vehicle's value. In each ``component`` the one row with the most
specific selector applies (a geo-object's own row wins over its road class's, which
wins over a row for every geo-object); two rows of one component that could both
apply to one vehicle on one geo-object are refused when the file is read, so no
fee depends on the order of rows. The passage's rate is the sum over components.

fee = (Σ per_passage + Σ per_km × length_km) × band factor, rounded once, half-up, to
the currency's minor unit; ``length_km`` is the section's length in whole metres (the
tariff's own ``[length_km]`` entry when it has one).
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass, field
from decimal import Decimal
from zoneinfo import ZoneInfo

from tollcli.charging.money import money, where
from tollcli.geoobjects.road_sections import road_of
from tollcli.errors import DataError

TABLE_KEYS = ("name", "valid_from", "valid_until", "rate")
SELECTORS = ("geoobject", "road_class")
AMOUNTS = ("per_km", "per_passage")
#: the attribute every vehicle has (``--vehicle-class``); a tariff may filter on it when it declares its values
VEHICLE_CLASS = "vehicle_class"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class Rate:
    """One row of a table: what it applies to and what it charges."""

    component: str
    line: int  # of its [[table.rate]] header (0: not found)
    geoobjects: frozenset[str] | None
    road_classes: frozenset[str] | None
    filters: tuple[tuple[str, frozenset[str]], ...]  # (attribute, values), sorted by attribute
    per_km: Decimal
    per_passage: Decimal

    @property
    def level(self) -> int:
        """How specific the selector is: 2 a geo-object, 1 a road class, 0 every geo-object."""
        return 2 if self.geoobjects is not None else 1 if self.road_classes is not None else 0

    def selects(self, geoobject: str, road_class: str) -> bool:
        if self.geoobjects is not None:  # a section cut from a road at its junctions (ID/k) has the road's rates
            return geoobject in self.geoobjects or road_of(geoobject) in self.geoobjects
        return self.road_classes is None or road_class in self.road_classes


@dataclass(frozen=True)
class RateTable:
    name: str
    valid_from_utc: dt.datetime
    valid_until_utc: dt.datetime | None  # None: until the next table (or for ever)
    rates: tuple[Rate, ...]
    line: int = 0


@dataclass(frozen=True)
class Price:
    """What one charged passage costs and why."""

    fee: Decimal
    band: str
    table: str = ""
    length_km: Decimal | None = None
    per_km: Decimal | None = None
    per_passage: Decimal | None = None
    components: dict = field(default_factory=dict)  # component → {"per_km", "per_passage", "line"}


def _strings(value, where_: str, what: str) -> frozenset[str]:
    """A string, whole number or a non-empty list of them → the set of their texts."""
    items = value if isinstance(value, list) else [value]
    if not items or any(isinstance(v, bool) or not isinstance(v, (str, int)) for v in items):
        raise DataError(f"{where_}: {what} must be a text, a whole number or a list of them, got {value!r}")
    return frozenset(str(v) for v in items)


def parse_vehicle(section, path: str, text: str) -> dict[str, frozenset[str]]:
    """``[vehicle]``: attribute → the values it may take."""
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise DataError(f"{where(path, text, 'vehicle')}: [vehicle] must be a table of attribute = [values]")
    out = {}
    for name, values in section.items():
        if not _NAME.match(name):
            raise DataError(f"{where(path, text, name)}: vehicle attribute {name!r} is not a plain name")
        if name in (*SELECTORS, *AMOUNTS, "component"):
            raise DataError(f"{where(path, text, name)}: {name!r} cannot be a vehicle attribute (it is a rate key)")
        out[name] = _strings(values, f"{where(path, text, name)}: vehicle attribute {name!r}", "its values")
    return out


def _header_lines(text: str, header: str) -> list[int]:
    return [n for n, line in enumerate(text.splitlines(), 1) if re.match(rf"^\s*\[\[\s*{re.escape(header)}\s*\]\]", line)]


def _instant(value, zone: ZoneInfo, where_: str) -> dt.datetime:
    """A TOML date or date-time (local to the tariff's zone unless it has an offset) → UTC."""
    if isinstance(value, dt.datetime):
        local = value if value.tzinfo is not None else value.replace(tzinfo=zone)
    elif isinstance(value, dt.date):
        local = dt.datetime(value.year, value.month, value.day, tzinfo=zone)
    else:
        raise DataError(f"{where_}: must be a TOML date (2024-07-01) or date-time (2024-07-01T00:00:00), got {value!r}")
    return local.astimezone(dt.timezone.utc)


def parse_tables(items, vehicle: dict[str, frozenset[str]], zone: ZoneInfo, path: str, text: str) -> tuple[RateTable, ...]:
    """``[[table]]`` and their ``[[table.rate]]`` rows, checked; sorted by validity."""
    if not isinstance(items, list) or not items:
        raise DataError(f"{where(path, text, 'table')}: [[table]] must be an array of tables")
    table_lines, rate_lines = _header_lines(text, "table"), _header_lines(text, "table.rate")
    tables, n_rate = [], 0
    for i, item in enumerate(items):
        line = table_lines[i] if i < len(table_lines) else 0
        here = f"{path}:{line}" if line else path
        if not isinstance(item, dict):
            raise DataError(f"{here}: a [[table]] must be a table")
        for key in item:
            if key not in TABLE_KEYS:
                raise DataError(f"{where(path, text, key, line)}: table: unknown key {key!r} (a table has {', '.join(TABLE_KEYS)})")
        if "valid_from" not in item:
            raise DataError(f"{here}: table: missing valid_from (the date it comes into force)")
        start = _instant(item["valid_from"], zone, f"{where(path, text, 'valid_from', line)}: valid_from")
        end = _instant(item["valid_until"], zone, f"{where(path, text, 'valid_until', line)}: valid_until") if "valid_until" in item else None
        if end is not None and end <= start:
            raise DataError(f"{where(path, text, 'valid_until', line)}: valid_until is not after valid_from")
        name = str(item.get("name", item["valid_from"]))
        rows = item.get("rate")
        if not isinstance(rows, list) or not rows:
            raise DataError(f"{here}: table {name!r} has no [[table.rate]] rows")
        rates = []
        for row in rows:
            row_line = rate_lines[n_rate] if n_rate < len(rate_lines) else 0
            n_rate += 1
            rates.append(_rate(row, vehicle, path, text, row_line))
        _refuse_ambiguous(rates, path, name)
        tables.append(RateTable(name, start, end, tuple(rates), line))
    tables.sort(key=lambda t: t.valid_from_utc)
    for a, b in zip(tables, tables[1:]):
        if a.valid_from_utc == b.valid_from_utc:
            raise DataError(f"{path}:{b.line}: tables {a.name!r} and {b.name!r} come into force at the same time")
        if a.valid_until_utc is not None and a.valid_until_utc > b.valid_from_utc:
            raise DataError(f"{path}:{a.line}: table {a.name!r} is valid until after table {b.name!r} comes into force")
    return tuple(tables)


def _rate(row, vehicle: dict[str, frozenset[str]], path: str, text: str, line: int) -> Rate:
    here = f"{path}:{line}" if line else path
    if not isinstance(row, dict):
        raise DataError(f"{here}: a [[table.rate]] must be a table")
    known = ("component", *SELECTORS, *AMOUNTS, *vehicle)
    for key in row:
        if key not in known:
            hint = " (declare vehicle attributes under [vehicle])" if key not in ("component", *SELECTORS, *AMOUNTS) else ""
            raise DataError(f"{where(path, text, key, line)}: rate: unknown key {key!r} (a rate has "
                            f"{', '.join(known)}){hint}")  # fmt: skip
    if "geoobject" in row and "road_class" in row:
        raise DataError(f"{here}: rate: give geoobject or road_class, not both")
    if not any(k in row for k in AMOUNTS):
        raise DataError(f"{here}: rate: no amount (per_km and/or per_passage)")
    amounts = {k: money(row.get(k, 0), f"{where(path, text, k, line)}: rate {k}") for k in AMOUNTS}
    filters = []
    for name in sorted(set(row) & set(vehicle)):
        values = _strings(row[name], f"{where(path, text, name, line)}: rate {name}", name)
        unknown = sorted(values - vehicle[name])
        if unknown:
            raise DataError(f"{where(path, text, name, line)}: rate: {name} {unknown[0]!r} is not one of the values "
                            f"[vehicle] declares ({', '.join(sorted(vehicle[name]))})")  # fmt: skip
        filters.append((name, values))
    component = row.get("component", "rate")
    if not isinstance(component, str) or not component:
        raise DataError(f"{where(path, text, 'component', line)}: rate: component must be a name")
    select = {k: _strings(row[k], f"{where(path, text, k, line)}: rate {k}", k) if k in row else None for k in SELECTORS}
    return Rate(component, line, select["geoobject"], select["road_class"], tuple(filters), amounts["per_km"], amounts["per_passage"])


def _refuse_ambiguous(rates: list[Rate], path: str, table: str) -> None:
    """DataError when two rows of one component and one selector level could apply to the same passage."""
    for i, a in enumerate(rates):
        for b in rates[i + 1 :]:
            if a.component != b.component or a.level != b.level:
                continue
            mine, theirs = (a.geoobjects or a.road_classes), (b.geoobjects or b.road_classes)
            if mine is not None and not (mine & theirs):
                continue
            fa, fb = dict(a.filters), dict(b.filters)
            if all(fa[k] & fb[k] for k in fa.keys() & fb.keys()):
                raise DataError(f"{path}:{b.line}: table {table!r}: this rate and the one at line {a.line} both apply "
                                f"to one vehicle (component {a.component!r}): make their attributes exclusive")  # fmt: skip


def table_in_force(tables: tuple[RateTable, ...], entry_utc: dt.datetime, source: str) -> RateTable:
    """The table in force at ``entry_utc`` (a DataError naming the time when none is)."""
    found = None
    for k, table in enumerate(tables):
        end = table.valid_until_utc or (tables[k + 1].valid_from_utc if k + 1 < len(tables) else None)
        if table.valid_from_utc <= entry_utc and (end is None or entry_utc < end):
            found = table
    if found is None:
        raise DataError(f"{source}: no tariff table in force at {entry_utc.astimezone(dt.timezone.utc):%Y-%m-%dT%H:%M:%SZ}")
    return found


def chosen_rates(table: RateTable, geoobject: str, road_class: str, vehicle: dict[str, str], source: str) -> dict[str, Rate]:
    """Component → the row that applies to this vehicle on this geo-object (the most specific selector)."""
    chosen: dict[str, Rate] = {}
    for rate in table.rates:
        if not rate.selects(geoobject, road_class):
            continue
        given = [(k, v) for k, v in rate.filters if k in vehicle]
        if any(vehicle[k] not in v for k, v in given):
            continue
        missing = [k for k, _ in rate.filters if k not in vehicle]
        if missing:
            raise DataError(f"{source}:{rate.line}: this rate depends on the vehicle's {missing[0]}: give it "
                            f"(--vehicle-attr {missing[0]}=…)")  # fmt: skip
        best = chosen.get(rate.component)
        if best is None or rate.level > best.level:
            chosen[rate.component] = rate
    if not chosen:
        described = ", ".join(f"{k}={v}" for k, v in sorted(vehicle.items()))
        raise DataError(f"{source}: table {table.name!r} has no rate for geo-object {geoobject!r} ({road_class}) "
                        f"and vehicle {described}")  # fmt: skip
    return dict(sorted(chosen.items()))


def check_vehicle(vehicle: dict[str, str], declared: dict[str, frozenset[str]], source: str) -> str:
    """Why ``vehicle`` does not fit the tariff's ``[vehicle]`` ('' when it does)."""
    for name, value in sorted(vehicle.items()):
        if name == VEHICLE_CLASS and name not in declared:
            continue
        if name not in declared:
            names = ", ".join(sorted(declared)) or "none"
            return f"{name!r} is not a vehicle attribute of the tariff {source} (it has {names})"
        if value not in declared[name]:
            return f"{name} {value!r} is not one of {', '.join(sorted(declared[name]))} (the tariff {source})"
    return ""
