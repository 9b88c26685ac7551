"""GPS time ↔ UTC for receiver files that count time in the GPS scale (GSDC, RINEX, GnssLogger).

GPS time runs ahead of UTC by the leap seconds inserted since 1980-01-06; the
table below lists them. Times are numpy ``datetime64`` or seconds since the GPS epoch.
"""

from __future__ import annotations

import numpy as np

GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ms")
_GPS_EPOCH_NS = np.datetime64("1980-01-06T00:00:00", "ns")
#: GPS − UTC in seconds from each date on (leap seconds since 1980)
LEAP_SECONDS = [
    ("1981-07-01", 1), ("1982-07-01", 2), ("1983-07-01", 3), ("1985-07-01", 4), ("1988-01-01", 5),
    ("1990-01-01", 6), ("1991-01-01", 7), ("1992-07-01", 8), ("1993-07-01", 9), ("1994-07-01", 10),
    ("1996-01-01", 11), ("1997-07-01", 12), ("1999-01-01", 13), ("2006-01-01", 14), ("2009-01-01", 15),
    ("2012-07-01", 16), ("2015-07-01", 17), ("2017-01-01", 18),
]  # fmt: skip


def gps_millis_to_utc(millis: np.ndarray) -> np.ndarray:
    """GPS milliseconds since 1980-01-06 → UTC ``datetime64[ms]`` (leap seconds removed)."""
    gps = GPS_EPOCH + np.asarray(millis, dtype=np.int64).astype("timedelta64[ms]")
    leap = np.zeros(gps.shape, dtype=np.int64)
    for date, seconds in LEAP_SECONDS:
        leap = np.where(gps >= np.datetime64(date, "ms") + np.timedelta64(seconds, "s"), seconds, leap)
    return gps - leap.astype("timedelta64[s]")


def gps_seconds(times: np.ndarray) -> np.ndarray:
    """datetime64 (GPS time scale) → seconds since 1980-01-06."""
    return (np.asarray(times, dtype="datetime64[ns]") - _GPS_EPOCH_NS).astype(np.int64) / 1e9


def leap_seconds_at_gps(gps_s: np.ndarray) -> np.ndarray:
    """GPS − UTC (s) at GPS seconds since 1980-01-06 (each leap second counts from its GPS instant on)."""
    gps_s = np.asarray(gps_s, float)
    leap = np.zeros(gps_s.shape)
    for date, seconds in LEAP_SECONDS:
        at = (np.datetime64(date, "s") - np.datetime64("1980-01-06T00:00:00", "s")).astype(np.int64) + seconds
        leap = np.where(gps_s >= at, float(seconds), leap)
    return leap
