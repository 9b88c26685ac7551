"""How far a log's vehicle drove: from the receiver's speed where it gave one, else along its positions.

Summing the steps between fixes adds their noise to the distance: a receiver standing still for ten minutes
(``sirf2.log``) "drove" 0.62 km, and the snapshot fixes of the Berlin drive (errors of 15–45 m, five a second) add
up to 8.2 km for a drive of 1.55 km. The speed a receiver reports comes from the Doppler shifts, not from the
positions, and is zero when the vehicle stands. So each interval between two epochs with a position counts

* the mean of the speeds at its ends times its length, where both ends have a speed and the interval is at most
  :data:`SPEED_GAP_S` long (a gap the speed cannot bridge);
* else the great-circle step between the two positions (the shortest the vehicle can have driven).

A pseudorange log placed by the trajectory estimator has its intervals without a speed measured along the trajectory,
not along the snapshot fixes. Against the reference trajectories in ``../shared/data``: the Berlin drive (odometer
speed) 1.56 km for 1.55 km (its snapshot fixes: 8.24 km; its smoothed trajectory alone 1.57 km); the u-blox walk
(Doppler speed) 130 m for 129 m (its fixes 247 m; its trajectory alone 99 m: the motion model smooths a walker's
meanders away).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.geodesy import great_circle_distance_m

#: the longest interval (s) the speeds at its two ends measure: beyond, the vehicle may have stopped and gone again
SPEED_GAP_S = 10.0


@dataclass
class DistanceCarry:
    """The last epoch with a position of the chunks before (time s, latitude, longitude, speed m/s), and the sums."""

    last: tuple[float, float, float, float] | None = None
    distance_m: float = 0.0
    by_speed: int = 0
    by_fixes: int = 0


def add_distance(carry: DistanceCarry, t_s: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, speed_mps: np.ndarray | None) -> None:
    """Add one chunk's epochs (time s, position deg, speed m/s or None; in log order) to ``carry``."""
    ok = np.isfinite(lat_deg) & np.isfinite(lon_deg)
    t, lat, lon = (np.asarray(a, float)[ok] for a in (t_s, lat_deg, lon_deg))
    v = np.full(t.size, np.nan) if speed_mps is None else np.asarray(speed_mps, float)[ok]
    if carry.last is not None and t.size:
        t, lat, lon, v = (np.r_[carry.last[i], a] for i, a in enumerate((t, lat, lon, v)))
    if t.size == 0:
        return
    carry.last = (float(t[-1]), float(lat[-1]), float(lon[-1]), float(v[-1]))
    if t.size < 2:
        return
    dt = np.diff(t)
    mean_v = (v[1:] + v[:-1]) / 2
    by_speed = np.isfinite(mean_v) & (mean_v >= 0) & np.isfinite(dt) & (dt >= 0) & (dt <= SPEED_GAP_S)
    step = great_circle_distance_m(lat[:-1], lon[:-1], lat[1:], lon[1:])
    carry.distance_m += float(np.sum(np.where(by_speed, mean_v * dt, step)))
    carry.by_speed += int(by_speed.sum())
    carry.by_fixes += int((~by_speed).sum())


def distance_from(carry: DistanceCarry, positions: str = "fixes") -> str:
    """What the distance was measured by: ``speed``, the ``positions`` (``fixes``, or the trajectory's name), both
    (with the share of the intervals by speed), or ``none``."""
    n = carry.by_speed + carry.by_fixes
    if n == 0:
        return "none"
    if carry.by_fixes == 0:
        return "speed"
    if carry.by_speed == 0:
        return positions
    return f"speed ({100.0 * carry.by_speed / n:.0f} % of the intervals) and {positions}"
