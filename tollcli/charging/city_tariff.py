"""City tariffs in TOML (``scheme = "city"``): rates per gantry passage by time band, day type and season; a zone's
daily charge; the calendar of free days; the single-charge rule and a daily cap. ``docs/city.md`` documents the format
with the Gothenburg, Stockholm and zone examples of ``geoobjects/``. A short one::

    scheme = "city"
    currency = "SEK"
    minor_unit = 0
    timezone = "Europe/Stockholm"          # bands, days and the calendar are local times of this zone

    [calendar]
    free_weekdays = ["sat", "sun"]
    holidays = ["2026-01-01", "2026-01-06"]
    free_days_before_holidays = true
    free_months = [7]
    charged_first_weekdays_of_free_months = 0   # Stockholm: 5 (July is charged on its first five weekdays)

    [[rate]]                               # the first rate holding a crossing prices it
    start = "07:00"                        # local, inclusive
    end = "08:00"                          # exclusive
    amount = 22                            # or a table by vehicle class: { car = 22, truck = 44 }
    # optional: gantries = ["G1"], days = ["mon", …], months = [1, …], direction = "left_to_right",
    # attributes = { euro_class = ["euro5", "euro6"] } (only vehicles with one of these values)

    [single_charge]
    window_min = 60                        # passages within 60 minutes of a window's first: charged once, the highest

    [daily_cap]
    amount = 60                            # per vehicle and local day, over everything this tariff charges

    [[zone_charge]]                        # presence in a zone in charging hours: charged once a day
    start = "07:00"
    end = "18:00"
    amount = 15
    # optional: zones = ["Z1"], days = [...], calendar = false (the free days do not apply),
    # attributes = { euro_class = ["euro3", "euro4"] } (only vehicles with one of these values)

A vehicle class a rate's amount table does not name pays nothing for that rate (an exemption, said in the line).
Unknown keys, days, classes or a time that is not HH:MM are errors naming the file and line. Money is ``Decimal``.
"""

from __future__ import annotations

import datetime as dt
import tomllib
from dataclasses import dataclass
from decimal import Decimal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from tollcli.charging.money import at_least_minor_unit, line_of, money, where
from tollcli.charging.tariffs import DAYS, KNOWN_VEHICLE_CLASSES, _day, _minutes, nth_table_line
from tollcli.errors import DataError, UsageError

TOP_KEYS = ("scheme", "currency", "minor_unit", "timezone", "vehicle_classes", "calendar", "rate", "single_charge", "daily_cap",
            "zone_charge", "name")  # fmt: skip
CALENDAR_KEYS = ("free_weekdays", "holidays", "free_days_before_holidays", "free_months", "charged_first_weekdays_of_free_months",
                 "free_dates")  # fmt: skip
RATE_KEYS = ("start", "end", "amount", "gantries", "days", "months", "direction", "attributes", "name")
ZONE_KEYS = ("start", "end", "amount", "zones", "days", "months", "calendar", "attributes", "name")


@dataclass(frozen=True)
class Calendar:
    free_weekdays: frozenset[int] = frozenset()
    holidays: frozenset[dt.date] = frozenset()
    free_days_before_holidays: bool = False
    free_months: frozenset[int] = frozenset()
    charged_first_weekdays_of_free_months: int = 0
    free_dates: frozenset[dt.date] = frozenset()

    def free_reason(self, day: dt.date) -> str:
        """Why ``day`` (local) is free of charge ('' when it is charged)."""
        if day.weekday() in self.free_weekdays:
            return f"free weekday ({DAYS[day.weekday()]})"
        if day in self.holidays:
            return "public holiday"
        if self.free_days_before_holidays and day + dt.timedelta(days=1) in self.holidays:
            return "day before a public holiday"
        if day in self.free_dates:
            return "free date"
        if day.month in self.free_months:
            first = dt.date(day.year, day.month, 1)
            weekdays = sum(1 for k in range((day - first).days + 1) if (first + dt.timedelta(days=k)).weekday() < 5)
            if not (day.weekday() < 5 and weekdays <= self.charged_first_weekdays_of_free_months):
                return f"free month ({day.strftime('%B').lower()})"
        return ""


@dataclass(frozen=True)
class TimedAmount:
    """A rate (a gantry passage) or a zone charge: when it holds and what it costs by vehicle class."""

    name: str
    start_min: int
    end_min: int  # exclusive; < start_min: wraps past midnight
    amounts: dict[str, Decimal] | None  # by vehicle class; None: the same for every class (``amount``)
    amount: Decimal
    objects: frozenset[str] | None  # gantries (rates) or zones (zone charges) it applies to; None: all
    days: frozenset[int]
    months: frozenset[int]
    direction: str = ""  # rates: '' (either) or the crossing direction it prices
    calendar: bool = True  # zone charges: whether the calendar's free days apply
    attributes: dict[str, frozenset[str]] | None = None  # only vehicles with one of these values

    def holds(self, local: dt.datetime, obj: str, direction: str = "") -> bool:
        minute = local.hour * 60 + local.minute
        in_time = (self.start_min <= minute < self.end_min) if self.start_min < self.end_min else (minute >= self.start_min or minute < self.end_min)
        return (in_time and local.weekday() in self.days and local.month in self.months
                and (self.objects is None or obj in self.objects) and (not self.direction or self.direction == direction))  # fmt: skip

    def price(self, vehicle_class: str) -> Decimal | None:
        """The amount for a vehicle class (None: the class is exempt from this rate)."""
        return self.amount if self.amounts is None else self.amounts.get(vehicle_class)

    def applies_to(self, attrs: dict[str, str]) -> bool:
        return not self.attributes or all(attrs.get(k) in values for k, values in self.attributes.items())


@dataclass(frozen=True)
class CityTariff:
    currency: str
    minor_unit: int
    timezone: str
    vehicle_classes: tuple[str, ...]
    calendar: Calendar
    rates: tuple[TimedAmount, ...]
    zone_charges: tuple[TimedAmount, ...]
    single_charge_min: float | None
    daily_cap: Decimal | None
    source: str = ""
    name: str = ""

    @property
    def zone(self) -> ZoneInfo:
        return ZoneInfo(self.timezone)

    def rate_for(self, local: dt.datetime, gantry: str, direction: str, attrs: dict | None = None) -> TimedAmount | None:
        """The first rate holding at a local time for a gantry, a direction and the vehicle's attributes."""
        return next((r for r in self.rates if r.holds(local, gantry, direction) and r.applies_to(attrs or {})), None)

    def crossing_price(self, times_s, gantry: str, direction: str, vehicle_class: str, attrs: dict | None = None):
        """(rate, amount) of a crossing known to lie between the UTC times ``times_s`` (s since 1970: the interpolated
        time and the evidence on either side): the lowest of the rates holding at them — the benefit of the doubt near a
        band's edge; amount None: the class is exempt; None when no rate holds."""
        found = []
        for t in times_s:
            rate = self.rate_for(dt.datetime.fromtimestamp(t, dt.UTC).astimezone(self.zone), gantry, direction, attrs)
            if rate is not None:
                found.append(rate)
        if not found:
            return None
        priced = [(r, r.price(vehicle_class)) for r in found]
        exempt = next(((r, a) for r, a in priced if a is None), None)
        return exempt if exempt is not None else min(priced, key=lambda p: p[1])

    def check_against(self, ids: list[str], kinds, geo: str) -> None:
        """DataError when a rate names a gantry, or a zone charge a zone, that the geo-object file does not hold (a typo
        would silently never charge)."""
        have = {kind: {i for i, k in zip(ids, kinds) if k == kind} for kind in ("gantry", "zone")}
        for what, items, kind in (("rate", self.rates, "gantry"), ("zone_charge", self.zone_charges, "zone")):
            for item in items:
                missing = sorted((item.objects or set()) - have[kind])
                if missing:
                    raise DataError(f"{self.source}: {what} {item.name}: {missing[0]} is not a {kind} of {geo}")

    def describe(self) -> dict:
        """The tariff's rules as the invoice records them."""
        return {"scheme": "city", "single_charge_window_min": self.single_charge_min,
                "daily_cap": None if self.daily_cap is None else str(self.daily_cap), "timezone": self.timezone}  # fmt: skip


def is_city_tariff(path: str) -> bool:
    """Whether a tariff file says ``scheme = "city"`` (read as TOML; False when it cannot be read: its loader says why)."""
    try:
        with open(path, "rb") as fh:
            doc = tomllib.loads(fh.read().decode("utf-8-sig"))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return False
    return isinstance(doc, dict) and doc.get("scheme") == "city"


def load_city_tariff(path: str) -> CityTariff:
    """Read and check a city tariff (DataError naming the file, line and key)."""
    try:
        with open(path, "rb") as fh:
            text = fh.read().decode("utf-8-sig")
        doc = tomllib.loads(text, parse_float=Decimal)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a TOML tariff: {' '.join(str(exc).split())}") from None
    _known(doc, TOP_KEYS, path, text, "the tariff")
    if doc.get("scheme") != "city":
        raise DataError(f"{where(path, text, 'scheme')}: a city tariff says scheme = \"city\"")
    currency, minor = doc.get("currency"), doc.get("minor_unit", 2)
    if not isinstance(currency, str) or len(currency) != 3 or not currency.isupper():
        raise DataError(f"{where(path, text, 'currency')}: currency must be an ISO 4217 code such as SEK, got {currency!r}")
    if isinstance(minor, bool) or not isinstance(minor, int) or not 0 <= minor <= 4:
        raise DataError(f"{where(path, text, 'minor_unit')}: minor_unit must be 0 … 4 decimals, got {minor!r}")
    tz = doc.get("timezone")
    try:
        ZoneInfo(str(tz))
    except (ZoneInfoNotFoundError, ValueError):
        raise DataError(f"{where(path, text, 'timezone')}: unknown time zone {tz!r} (an IANA name such as Europe/Stockholm)") from None
    classes = doc.get("vehicle_classes", list(KNOWN_VEHICLE_CLASSES))
    if not isinstance(classes, list) or not classes or not all(isinstance(c, str) and c for c in classes):
        raise DataError(f"{where(path, text, 'vehicle_classes')}: vehicle_classes must be a list of class names")
    classes = tuple(classes)
    rates = tuple(_timed(item, i, "rate", RATE_KEYS, path, text, minor, classes) for i, item in enumerate(_tables(doc.get("rate"), "rate", path)))
    zones = tuple(_timed(item, i, "zone_charge", ZONE_KEYS, path, text, minor, classes)
                  for i, item in enumerate(_tables(doc.get("zone_charge"), "zone_charge", path)))  # fmt: skip
    if not rates and not zones:
        raise DataError(f"{path}: a city tariff needs a [[rate]] or a [[zone_charge]]")
    single = doc.get("single_charge")
    window = None
    if single is not None:
        _known(single, ("window_min",), path, text, "[single_charge]")
        window = single.get("window_min")
        if isinstance(window, bool) or not isinstance(window, (int, Decimal)) or not 0 < window <= 1440:
            raise DataError(f"{where(path, text, 'window_min')}: window_min must be minutes, > 0 and ≤ 1440")
        window = float(window)
    cap = doc.get("daily_cap")
    if cap is not None:
        _known(cap, ("amount",), path, text, "[daily_cap]")
        if "amount" not in cap:
            raise DataError(f"{where(path, text, 'daily_cap')}: [daily_cap] needs an amount")
        cap = at_least_minor_unit(money(cap["amount"], where(path, text, "amount", line_of(text, "daily_cap"))), minor, path)
    return CityTariff(currency, minor, str(tz), classes, _calendar(doc.get("calendar"), path, text), rates, zones, window, cap, path,
                      str(doc.get("name", "")))  # fmt: skip


def _known(table, keys, path, text, what) -> None:
    if not isinstance(table, dict):
        raise DataError(f"{path}: {what} must be a table")
    for key in table:
        if key not in keys:
            raise DataError(f"{where(path, text, key)}: {what}: unknown key {key!r} (known: {', '.join(keys)})")


def _tables(items, name, path) -> list:
    if items is None:
        return []
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise DataError(f"{path}: [[{name}]] must be an array of tables")
    return items


def _timed(item: dict, index: int, name: str, keys, path, text, minor, classes) -> TimedAmount:
    header = nth_table_line(text, name, index)
    here = f"{path}:{header}: {name} {index + 1}" if header else f"{path}: {name} {index + 1}"
    for key in item:
        if key not in keys:
            raise DataError(f"{where(path, text, key, header)}: {name} {index + 1}: unknown key {key!r} (known: {', '.join(keys)})")
    for key in ("start", "end", "amount"):
        if key not in item:
            raise DataError(f"{here}: missing {key}")
    start = _minutes(item["start"], here)
    end = 1440 if item["end"] == "24:00" else _minutes(item["end"], here)  # (24:00: to the day's end)
    if start == end:
        raise DataError(f"{here}: start and end are equal")
    raw = item["amount"]
    amounts = None
    if isinstance(raw, dict):
        for vc in raw:
            if vc not in classes:
                raise DataError(f"{where(path, text, vc, header)}: {name} {index + 1}: unknown vehicle class {vc!r} "
                                f"(the tariff's: {', '.join(classes)})")  # fmt: skip
        amounts = {vc: at_least_minor_unit(money(v, f"{here} amount.{vc}"), minor, here) for vc, v in raw.items()}
        amount = Decimal(0)
    else:
        amount = at_least_minor_unit(money(raw, f"{here} amount"), minor, here)
    days = item.get("days", list(DAYS))
    if not isinstance(days, list) or not days or any(_day(d) is None for d in days):
        raise DataError(f"{where(path, text, 'days', header)}: {name} {index + 1}: days must be a list of mon … sun")
    months = item.get("months", list(range(1, 13)))
    if not isinstance(months, list) or not months or any(isinstance(m, bool) or not isinstance(m, int) or not 1 <= m <= 12 for m in months):
        raise DataError(f"{where(path, text, 'months', header)}: {name} {index + 1}: months must be a list of 1 … 12")
    listed = item.get("gantries" if name == "rate" else "zones")
    if listed is not None and (not isinstance(listed, list) or not all(isinstance(g, str) for g in listed)):
        raise DataError(f"{here}: {'gantries' if name == 'rate' else 'zones'} must be a list of ids")
    direction = item.get("direction", "")
    if direction not in ("", "left_to_right", "right_to_left"):
        raise DataError(f"{where(path, text, 'direction', header)}: {name} {index + 1}: direction must be left_to_right or right_to_left")
    calendar = item.get("calendar", True)
    if not isinstance(calendar, bool):
        raise DataError(f"{where(path, text, 'calendar', header)}: {name} {index + 1}: calendar must be true or false")
    attrs = item.get("attributes")
    if attrs is not None:
        if not isinstance(attrs, dict) or not all(isinstance(v, list) and v and all(isinstance(x, str) for x in v) for v in attrs.values()):
            raise DataError(f"{where(path, text, 'attributes', header)}: {name} {index + 1}: attributes maps a name to a list of values")
        attrs = {str(k): frozenset(v) for k, v in attrs.items()}
    default = f"{item['start']}–{item['end']}" if name == "rate" else f"{name}{index + 1}"  # a rate is named by its band
    return TimedAmount(str(item.get("name", default)), start, end, amounts, amount,
                       None if listed is None else frozenset(listed), frozenset(_day(d) for d in days), frozenset(months),
                       direction, calendar, attrs)  # fmt: skip


def _calendar(table, path, text) -> Calendar:
    if table is None:
        return Calendar()
    _known(table, CALENDAR_KEYS, path, text, "[calendar]")

    def dates(key):
        values = table.get(key, [])
        out = set()
        for v in values if isinstance(values, list) else [values]:
            try:
                out.add(v if isinstance(v, dt.date) and not isinstance(v, dt.datetime) else dt.date.fromisoformat(str(v)))
            except ValueError:
                raise DataError(f"{where(path, text, key)}: {key}: {v!r} is not a date YYYY-MM-DD") from None
        return frozenset(out)

    weekdays = table.get("free_weekdays", [])
    if not isinstance(weekdays, list) or any(_day(d) is None for d in weekdays):
        raise DataError(f"{where(path, text, 'free_weekdays')}: free_weekdays must be a list of mon … sun")
    months = table.get("free_months", [])
    if not isinstance(months, list) or any(isinstance(m, bool) or not isinstance(m, int) or not 1 <= m <= 12 for m in months):
        raise DataError(f"{where(path, text, 'free_months')}: free_months must be a list of 1 … 12")
    before = table.get("free_days_before_holidays", False)
    first = table.get("charged_first_weekdays_of_free_months", 0)
    if not isinstance(before, bool):
        raise DataError(f"{where(path, text, 'free_days_before_holidays')}: true or false")
    if isinstance(first, bool) or not isinstance(first, int) or not 0 <= first <= 23:
        raise DataError(f"{where(path, text, 'charged_first_weekdays_of_free_months')}: a number of weekdays, 0 … 23")
    return Calendar(frozenset(_day(d) for d in weekdays), dates("holidays"), before, frozenset(months), first, dates("free_dates"))
