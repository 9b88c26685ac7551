"""Per-epoch quantities of a trip that the enforcement checks share: steps between fixes, C/N0 summaries, runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.geodesy import great_circle_distance_m


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


def cn0_summary(satellites: pd.DataFrame | None, n_epochs: int, first_epoch: int) -> pd.DataFrame:
    """Per epoch row: satellites with a C/N0, their median, 80th percentile and spread (dB-Hz)."""
    out = pd.DataFrame({"n_tracked": np.zeros(n_epochs, np.int64), "cn0_median": np.nan, "cn0_p80": np.nan, "cn0_std": np.nan})
    if satellites is None or satellites.empty:
        return out
    s = satellites[np.isfinite(satellites["cn0_dbhz"].to_numpy(float)) & (satellites["cn0_dbhz"].to_numpy(float) > 0)]
    if s.empty:
        return out
    g = s.groupby(s["epoch"].to_numpy() - first_epoch)["cn0_dbhz"]
    agg = pd.DataFrame({"n_tracked": g.size(), "cn0_median": g.median(), "cn0_p80": g.quantile(0.8), "cn0_std": g.std(ddof=0)})
    agg = agg[(agg.index >= 0) & (agg.index < n_epochs)]
    out.loc[agg.index, ["n_tracked", "cn0_median", "cn0_p80", "cn0_std"]] = agg.to_numpy()
    out["n_tracked"] = out["n_tracked"].astype(np.int64)
    return out


def runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """[start, end] index pairs (inclusive) of the runs of True in ``flag``."""
    f = np.concatenate([[False], np.asarray(flag, bool), [False]])
    d = np.diff(f.astype(np.int8))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def trailing_median(values: np.ndarray, t_s: np.ndarray, window_s: float) -> np.ndarray:
    """Median of ``values`` over the ``window_s`` seconds before each epoch (excluding it); NaN when none."""
    ok = np.isfinite(t_s).all() and np.all(np.diff(t_s) >= 0)
    if not ok:  # times not increasing (a spoofed or broken log): a window of as many epochs as seconds
        return pd.Series(values).shift(1).rolling(max(int(window_s), 3), min_periods=3).median().to_numpy(float)
    s = pd.Series(values, index=pd.to_datetime(t_s, unit="s"))
    med = s.rolling(f"{int(window_s * 1000)}ms", closed="left", min_periods=3).median()
    return med.to_numpy(float)
