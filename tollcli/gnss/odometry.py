"""A vehicle's odometry (wheel speed, yaw rate) resampled to the GNSS epochs: what moved between two epochs."""

from __future__ import annotations

import numpy as np


def interval_odometry(odometry_t_s: np.ndarray, speed_mps: np.ndarray, yaw_rate_radps: np.ndarray, epoch_t_s: np.ndarray,
                      max_gap_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Mean speed (m/s) and yaw rate (rad/s) over each interval between consecutive epochs (index: the interval's end
    epoch; the first is NaN), from odometry samples integrated by the trapezoid rule; NaN where the samples are more
    than ``max_gap_s`` apart inside or around the interval."""
    n = epoch_t_s.size
    nan = np.full(n, np.nan)
    ok = np.isfinite(odometry_t_s) & np.isfinite(speed_mps) & np.isfinite(yaw_rate_radps)
    t, v, w = odometry_t_s[ok], speed_mps[ok], yaw_rate_radps[ok]
    if t.size < 2 or n < 2:
        return nan, nan.copy()
    order = np.argsort(t, kind="stable")
    t, v, w = t[order], v[order], w[order]
    dist = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    turn = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    d_at, p_at = np.interp(epoch_t_s, t, dist), np.interp(epoch_t_s, t, turn)
    dt = np.diff(epoch_t_s)
    with np.errstate(invalid="ignore", divide="ignore"):
        speed = np.concatenate([[np.nan], np.diff(d_at) / dt])
        yaw = np.concatenate([[np.nan], np.diff(p_at) / dt])
    # an interval is unknown where a spacing of the samples that touch it exceeds max_gap_s (counted, not looped)
    big = np.concatenate([[0], np.cumsum(np.diff(t) > max_gap_s)])
    lo = np.searchsorted(t, epoch_t_s[:-1], side="right") - 1
    hi = np.searchsorted(t, epoch_t_s[1:], side="left")
    covered = (lo >= 0) & (hi < t.size)
    lo_c, hi_c = lo.clip(0, t.size - 1), hi.clip(0, t.size - 1)
    gapped = big[hi_c] - big[lo_c] > 0
    bad = np.concatenate([[True], ~covered | gapped | ~(dt > 0)])
    speed[bad], yaw[bad] = np.nan, np.nan
    return speed, yaw
