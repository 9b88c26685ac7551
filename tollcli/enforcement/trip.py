"""Per-epoch quantities of a trip that the enforcement checks share: steps between fixes, C/N0 summaries, runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.geodesy import great_circle_distance_m
from tollcli.io.columns import Columns, column_array


@dataclass
class Fixes:
    """The epochs with a usable position, and the steps between consecutive ones."""

    rows: np.ndarray  # row of each fix in the epoch table
    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    dt_s: np.ndarray  # (F-1,) time from the previous fix
    step_m: np.ndarray  # (F-1,) distance from the previous fix


def fixes(epochs: pd.DataFrame, t_s: np.ndarray) -> Fixes:
    lat = epochs["lat_deg"].to_numpy(float)
    lon = epochs["lon_deg"].to_numpy(float)
    valid = epochs["fix_valid"].to_numpy(bool) if "fix_valid" in epochs else np.ones(len(epochs), bool)
    rows = np.flatnonzero(valid & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(t_s))
    la, lo, t = lat[rows], lon[rows], t_s[rows]
    return Fixes(rows, t, la, lo, np.diff(t), great_circle_distance_m(la[:-1], lo[:-1], la[1:], lo[1:]))


def cn0_summary(satellites: pd.DataFrame | Columns | None, n_epochs: int, first_epoch: int) -> pd.DataFrame:
    """Per epoch row: satellites with a C/N0, their median, 80th percentile and spread (dB-Hz). ``satellites``: the
    satellite table (``epoch``, ``cn0_dbhz``), a DataFrame or the reader's columns.

    The percentile interpolates linearly between order statistics (pandas' and numpy's
    default); the spread is the population standard deviation (two passes).
    """
    n_tracked = np.zeros(n_epochs, np.int64)
    med, p80, std = np.full(n_epochs, np.nan), np.full(n_epochs, np.nan), np.full(n_epochs, np.nan)
    if satellites is not None and len(satellites):
        cn0 = column_array(satellites, "cn0_dbhz", float)
        row = column_array(satellites, "epoch", np.int64) - first_epoch
        keep = np.isfinite(cn0) & (cn0 > 0) & (row >= 0) & (row < n_epochs)
        x, r = _sorted_by_epoch(cn0[keep], row[keep])
        n_tracked = np.bincount(r, minlength=n_epochs).astype(np.int64)
        has = np.flatnonzero(n_tracked)
        if has.size:
            n = n_tracked[has]
            start = (np.cumsum(n_tracked) - n_tracked)[has]
            half = n // 2
            med[has] = np.where(n % 2 == 1, x[start + half], (x[start + half] + x[start + np.maximum(half - 1, 0)]) / 2.0)
            pos = 0.8 * (n - 1)
            lo = pos.astype(np.int64)
            frac = pos - lo
            low = x[start + lo]
            high = x[start + np.minimum(lo + 1, n - 1)]
            p80[has] = np.where(frac == 0.0, low, low + (high - low) * frac)
            mean = np.bincount(r, weights=x, minlength=n_epochs)[has] / n
            dev = x - np.repeat(mean, n)
            std[has] = np.sqrt(np.bincount(r, weights=dev * dev, minlength=n_epochs)[has] / n)
    return pd.DataFrame({"n_tracked": n_tracked, "cn0_median": med, "cn0_p80": p80, "cn0_std": std})


def _sorted_by_epoch(cn0: np.ndarray, row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The C/N0s (> 0) ordered by epoch row, then value, and their rows: ``np.lexsort((cn0, row))`` applied to both.

    Where every C/N0 is a whole number of dB-Hz below 256 (NMEA's, u-blox's), one sort of the exact key
    row·256 + C/N0 gives the same two arrays, to the bit, about ten times faster (a 4 880-epoch chunk's 150 000 values:
    1.4 ms against 14 ms)."""
    whole = cn0.size and row.min() >= 0 and row.max() < 1 << 40 and bool(np.all((cn0 < 256.0) & (cn0 == np.floor(cn0))))
    if not whole:
        order = np.lexsort((cn0, row))
        return cn0[order], row[order]
    key = np.sort(row * 256.0 + cn0)  # exact: row·256 < 2⁴⁸ and a whole C/N0 below 256
    r = (key // 256.0).astype(np.int64)
    return key - r * 256.0, r


def runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """[start, end] index pairs (inclusive) of the runs of True in ``flag``."""
    f = np.concatenate([[False], np.asarray(flag, bool), [False]])
    d = np.diff(f.astype(np.int8))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def times_increase(t_s: np.ndarray) -> bool:
    """Every time known and none going back (time windows apply)."""
    return bool(np.isfinite(t_s).all() and np.all(np.diff(t_s) >= 0))


def trailing_median(values: np.ndarray, t_s: np.ndarray, window_s: float, increasing: bool | None = None) -> np.ndarray:
    """Median of ``values`` over the ``window_s`` seconds before each epoch (excluding it); NaN when none.

    ``values``: one value per epoch, or a column per quantity (each column on its own).
    ``increasing``: whether time windows apply (default :func:`times_increase` of ``t_s``).
    """
    ok = times_increase(t_s) if increasing is None else (increasing and times_increase(t_s))
    frame = pd.DataFrame(np.asarray(values, float).reshape(len(t_s), -1))
    if not ok:  # times not increasing (a spoofed or broken log): a window of as many epochs as seconds
        med = frame.shift(1).rolling(max(int(window_s), 3), min_periods=3).median()
    else:
        frame.index = pd.to_datetime(t_s, unit="s")
        med = frame.rolling(f"{int(window_s * 1000)}ms", closed="left", min_periods=3).median()
    out = med.to_numpy(float)
    return out.reshape(np.shape(values))
