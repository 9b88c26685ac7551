"""A vehicle's odometry (wheel speed, yaw rate) resampled to the GNSS epochs: what moved between two epochs.

* :func:`interval_odometry`: the mean speed and yaw rate over each interval;
* :func:`interval_displacement`: the distance driven forward and to the left over each interval, in the frame of
  the heading at its start (the dead-reckoned arc, exact however long the interval and however the vehicle turned).

Both integrate the samples by the trapezoid rule; an interval is unknown (NaN) where the samples that touch it are
more than ``max_gap_s`` apart, and the first interval (before the first epoch) always is.
"""

from __future__ import annotations

import numpy as np


def _integrals(odometry_t_s, speed_mps, yaw_rate_radps, epoch_t_s, max_gap_s):
    """Cumulative distance, turn, ∫v·cos θ and ∫v·sin θ at the epochs (θ the turn since the first sample), and the
    unknown intervals; None where there are too few samples."""
    ok = np.isfinite(odometry_t_s) & np.isfinite(speed_mps) & np.isfinite(yaw_rate_radps)
    t, v, w = odometry_t_s[ok], speed_mps[ok], yaw_rate_radps[ok]
    if t.size < 2 or epoch_t_s.size < 2:
        return None
    order = np.argsort(t, kind="stable")
    t, v, w = t[order], v[order], w[order]
    dt = np.diff(t)

    def cumulative(f):
        return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * dt)])

    turn = cumulative(w)
    at = [np.interp(epoch_t_s, t, c) for c in (cumulative(v), turn, cumulative(v * np.cos(turn)), cumulative(v * np.sin(turn)))]
    # an interval is unknown where a spacing of the samples that touch it exceeds max_gap_s (counted, not looped)
    big = np.concatenate([[0], np.cumsum(dt > max_gap_s)])
    lo = np.searchsorted(t, epoch_t_s[:-1], side="right") - 1
    hi = np.searchsorted(t, epoch_t_s[1:], side="left")
    covered = (lo >= 0) & (hi < t.size)
    gapped = big[hi.clip(0, t.size - 1)] - big[lo.clip(0, t.size - 1)] > 0
    bad = np.concatenate([[True], ~covered | gapped | ~(np.diff(epoch_t_s) > 0)])
    return at, bad


def interval_odometry(odometry_t_s: np.ndarray, speed_mps: np.ndarray, yaw_rate_radps: np.ndarray, epoch_t_s: np.ndarray,
                      max_gap_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Mean speed (m/s) and yaw rate (rad/s, counter-clockwise positive) over each interval between consecutive epochs
    (index: the interval's end epoch)."""
    nan = np.full(epoch_t_s.size, np.nan)
    found = _integrals(odometry_t_s, speed_mps, yaw_rate_radps, epoch_t_s, max_gap_s)
    if found is None:
        return nan, nan.copy()
    (dist, turn, _, _), bad = found
    with np.errstate(invalid="ignore", divide="ignore"):
        dt = np.diff(epoch_t_s)
        speed = np.concatenate([[np.nan], np.diff(dist) / dt])
        yaw = np.concatenate([[np.nan], np.diff(turn) / dt])
    speed[bad], yaw[bad] = np.nan, np.nan
    return speed, yaw


def interval_displacement(odometry_t_s: np.ndarray, speed_mps: np.ndarray, yaw_rate_radps: np.ndarray, epoch_t_s: np.ndarray,
                          max_gap_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Distance (m) driven forward and to the left over each interval, in the frame of the heading at the interval's
    start: ∫v·cos(θ − θ₀) and ∫v·sin(θ − θ₀), θ the turn (counter-clockwise) since the first sample."""
    nan = np.full(epoch_t_s.size, np.nan)
    found = _integrals(odometry_t_s, speed_mps, yaw_rate_radps, epoch_t_s, max_gap_s)
    if found is None:
        return nan, nan.copy()
    (_, turn, c, s), bad = found
    c0, s0 = np.cos(turn[:-1]), np.sin(turn[:-1])
    dc, ds = np.diff(c), np.diff(s)
    forward = np.concatenate([[np.nan], c0 * dc + s0 * ds])
    left = np.concatenate([[np.nan], c0 * ds - s0 * dc])
    forward[bad], left[bad] = np.nan, np.nan
    return forward, left


#: the window over which the odometer's distance is compared with how far the fixes moved (s) …
PLAUSIBLE_WINDOW_S = 60.0
#: … and how much further the fixes may have moved than the odometer says (m): the block medians of city fixes are a
#: few tens of metres off, a car never covers a straight line longer than the road it drove
PLAUSIBLE_MARGIN_M = 100.0


def implausible_odometry(t_s: np.ndarray, fix_en_m: np.ndarray, forward_m: np.ndarray,
                         window_s: float = PLAUSIBLE_WINDOW_S, margin_m: float = PLAUSIBLE_MARGIN_M) -> np.ndarray:  # fmt: skip
    """The intervals (E,) whose odometry the fixes contradict: over a window of ``window_s`` the fixes moved further
    in a straight line than the odometer says the vehicle drove, by more than ``margin_m`` (a stuck or disconnected
    odometer reads 0 while the car drives; a straight line is never longer than the road).

    ``t_s`` epoch times (s, sorted), ``fix_en_m`` (E, 2) the snapshot fixes east-north (NaN where none), ``forward_m``
    (E,) the odometer's distance over the interval ending at each epoch. Where the fixes were is the median of the
    fixes of the window's first and last quarter (a single fix can be far off); every interval of a window that fails
    is marked."""
    import pandas as pd

    n = t_s.size
    bad = np.zeros(n, bool)
    if n < 3:
        return bad
    travelled = np.concatenate([[0.0], np.cumsum(np.abs(np.nan_to_num(forward_m[1:], nan=0.0)))])
    quarter = window_s / 4
    index = pd.to_datetime(t_s, unit="s")
    median = pd.DataFrame(fix_en_m, index=index).rolling(pd.Timedelta(seconds=quarter), min_periods=1).median().to_numpy()
    # the window ending at each epoch k: its last quarter's median is median[k], its first quarter's median[j]
    lo = np.searchsorted(t_s, t_s - window_s)  # the window's first epoch
    j = np.searchsorted(t_s, t_s[lo] + quarter, side="right") - 1
    full = t_s - t_s[lo] >= 0.9 * window_s
    moved = np.hypot(*(median - median[j]).T)
    driven = travelled - travelled[lo]
    with np.errstate(invalid="ignore"):
        fails = np.flatnonzero(full & (moved > driven + margin_m))
    if fails.size:  # mark the intervals lo+1 … k of each failing window (a difference array, no loop)
        mark = np.zeros(n + 1, np.int64)
        np.add.at(mark, lo[fails] + 1, 1)
        np.add.at(mark, fails + 1, -1)
        bad = np.cumsum(mark[:n]) > 0
    return bad
