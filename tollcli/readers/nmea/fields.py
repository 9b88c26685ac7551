"""Small pure converters for NMEA 0183 field text.

Every function takes the raw field text and returns a value in SI-ish units
(degrees, metres, seconds, metres per second). Empty fields give NaN; text that
is present but wrong raises ``ValueError`` so the caller can count the line as
malformed.
"""

from __future__ import annotations

import math
from functools import reduce
from operator import xor

NAN = math.nan
KNOT_MPS = 1852.0 / 3600.0  # 1 knot in m/s (exact)
KMH_MPS = 1.0 / 3.6


def checksum(body: str) -> int:
    """XOR of the characters between ``$`` and ``*`` (exclusive)."""
    return reduce(xor, body.encode("latin-1"), 0)


def num(field: str) -> float:
    """A decimal field → float; empty → NaN. Rejects NaN/inf spelled out."""
    if not field:
        return NAN
    value = float(field)
    if not math.isfinite(value):
        raise ValueError(f"non-finite number {field!r}")
    return value


def integer(field: str, missing: int = -1, lo: int = 0, hi: int = 32_767) -> int:
    """An integer field in [lo, hi]; empty → ``missing``; outside the range → ValueError."""
    if not field:
        return missing
    value = int(field)
    if not lo <= value <= hi:
        raise ValueError(f"{field!r} outside {lo}…{hi}")
    return value


def _ddmm(value: str, hemisphere: str, max_deg: float, negative: str, positive: str, what: str) -> float:
    """``(d)ddmm.mmmm`` + hemisphere → signed degrees (NaN when empty)."""
    if not value:
        return NAN
    raw = float(value)
    deg = math.floor(raw / 100.0)
    minutes = raw - 100.0 * deg
    out = deg + minutes / 60.0
    if raw < 0 or not (0.0 <= minutes < 60.0) or out > max_deg:
        raise ValueError(f"{what} out of range {value!r}")
    if hemisphere == negative:
        return -out
    if hemisphere not in (positive, ""):
        raise ValueError(f"{what} hemisphere {hemisphere!r}")
    return out


def lat_deg(value: str, hemisphere: str) -> float:
    """``ddmm.mmmm`` + N/S → signed latitude in degrees (NaN when empty)."""
    return _ddmm(value, hemisphere, 90.0, "S", "N", "latitude")


def lon_deg(value: str, hemisphere: str) -> float:
    """``dddmm.mmmm`` + E/W → signed longitude in degrees (NaN when empty)."""
    return _ddmm(value, hemisphere, 180.0, "W", "E", "longitude")


def time_of_day_s(value: str) -> float:
    """``hhmmss[.sss]`` → seconds since midnight UTC (NaN when empty).

    A leap second (``ss`` = 60) is accepted and gives 86 400 s at most.
    """
    if not value:
        return NAN
    if len(value) < 6 or not value[:6].isdigit():
        raise ValueError(f"time {value!r}")
    hh = int(value[0:2])
    mm = int(value[2:4])
    ss = float(value[4:])
    if hh > 23 or mm > 59 or not (0.0 <= ss < 61.0):
        raise ValueError(f"time out of range {value!r}")
    return hh * 3600.0 + mm * 60.0 + ss


def rmc_date_days(value: str) -> int:
    """RMC ``ddmmyy`` → days since 1970-01-01 (-1 when empty).

    Two-digit years: 80–99 → 19xx, 00–79 → 20xx (the usual NMEA pivot).
    """
    if not value:
        return -1
    if len(value) != 6 or not value.isdigit():
        raise ValueError(f"date {value!r}")
    yy = int(value[4:6])
    return civil_days(int(value[0:2]), int(value[2:4]), 1900 + yy if yy >= 80 else 2000 + yy)


def civil_days(day: int, month: int, year: int) -> int:
    """Calendar date → days since 1970-01-01 (validates the date)."""
    import datetime as _dt

    try:
        return (_dt.date(year, month, day) - _dt.date(1970, 1, 1)).days
    except (ValueError, OverflowError) as exc:
        raise ValueError(f"date {year:04d}-{month:02d}-{day:02d}: {exc}") from None
