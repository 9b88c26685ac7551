"""Small time helpers shared by the stages: epoch seconds, nearest-time lookup, ISO text."""

from __future__ import annotations

import numpy as np


#: the years a receiver's date may fall in: GPS time starts in 1980; beyond 2200 a date is a damaged field (and pandas'
#: nanosecond timestamps end in 2262)
PLAUSIBLE_YEARS = (1980, 2200)
#: the same span as ms since 1970: 1980-01-06 (GPS time's start) to 2200-01-01
PLAUSIBLE_MS = (315_964_800_000, 7_258_118_400_000)


def plausible_date(year, month, day, hour=0, minute=0, second=0):
    """Whether date and time fields (scalars or arrays) can be a receiver's: the year in :data:`PLAUSIBLE_YEARS`, the
    month, day, hour, minute and second (a leap second: 60) in range."""
    year, month, day, hour, minute, second = (np.asarray(a, dtype=np.int64) for a in (year, month, day, hour, minute, second))
    return ((year >= PLAUSIBLE_YEARS[0]) & (year <= PLAUSIBLE_YEARS[1]) & (month >= 1) & (month <= 12) & (day >= 1) & (day <= 31)
            & (hour >= 0) & (hour <= 23) & (minute >= 0) & (minute <= 59) & (second >= 0) & (second <= 60))  # fmt: skip


def epoch_seconds(epochs) -> np.ndarray:
    """Seconds since 1970 from ``time_utc`` where dated, else the time of day unwrapped over midnights."""
    if "time_utc" in epochs and epochs["time_utc"].notna().all() and len(epochs):
        return epochs["time_utc"].dt.tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64) / 1000.0
    if "tod_s" not in epochs:  # a table dated per epoch, some epochs not (a damaged time field): NaN there
        out = np.full(len(epochs), np.nan)
        if "time_utc" in epochs:
            dated = epochs["time_utc"].notna().to_numpy()
            out[dated] = epochs["time_utc"][dated].dt.tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64) / 1000.0
        return out
    tod = epochs["tod_s"].to_numpy(float)
    wraps = np.concatenate([[0], np.cumsum(np.diff(tod) < -43_200.0)]) if tod.size else np.zeros(0)
    return tod + 86_400.0 * wraps


def nearest_index(times: np.ndarray, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each query, the index into ``times`` (any order) of the nearest time and the absolute difference.

    ``times`` must not be empty.
    """
    times, queries = np.asarray(times), np.asarray(queries)
    order = np.argsort(times, kind="stable")
    ts = times[order]
    if ts.size == 1:
        j = np.zeros(queries.shape, dtype=np.int64)
    else:
        j = np.clip(np.searchsorted(ts, queries), 1, ts.size - 1)
        j = np.where(np.abs(ts[j - 1] - queries) <= np.abs(ts[j] - queries), j - 1, j)
    return order[j], np.abs(ts[j] - queries)


def iso_from_seconds(t_s: float) -> str:
    """Seconds since 1970 → ``YYYY-MM-DDTHH:MM:SS.mmmZ``."""
    import pandas as pd

    return pd.Timestamp(t_s, unit="s", tz="UTC").strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def iso_utc(values) -> np.ndarray:
    """Many timestamps (tz-aware or UTC-naive; Series, array or index) → ``YYYY-MM-DDTHH:MM:SS.mmmZ`` strings."""
    import pandas as pd

    dtype = getattr(values, "dtype", None)
    if isinstance(dtype, pd.DatetimeTZDtype):  # already times: only the zone to drop (no parsing pass)
        index = pd.DatetimeIndex(values).tz_convert(None)
    else:
        index = pd.DatetimeIndex(pd.to_datetime(values, utc=True)).tz_convert(None)
    text = np.datetime_as_string(index.to_numpy().astype("datetime64[ms]"), unit="ms")
    return np.char.add(text.astype(str), "Z").astype(object)
