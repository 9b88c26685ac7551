"""What the trajectory estimator reads, gathered once from a pseudorange log's epochs and measurements.

A pseudorange log's :class:`~tollcli.gnss.measurements.Measurements` carry, beside the RAIM's arrays, each
measurement's satellite (ECEF at transmission, ``sat_ecef_m``), its corrected pseudorange (``pr_m``: satellite
clock and atmosphere removed) and its receiver-clock group (``clock_index``: one clock per constellation). The
epoch table gives the times and, where the log has odometry (libRSF ``odom3``), the wheel speed and yaw rate
(``odometer_speed_mps``, ``yaw_rate_radps``) and the distance driven between epochs (``odometer_forward_m``,
``odometer_left_m``). Everything is in a local east-north-up frame at the log's first fix.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pandas as pd

from tollcli.geodesy import enu_rotation, geodetic2ecef
from tollcli.gnss.measurements import Measurements
from tollcli.gnss.odometry import implausible_odometry


@dataclass
class TrajectoryInputs:
    """Arrays of E epochs × N measurement slots (padded as :class:`Measurements`)."""

    t_s: np.ndarray  # (E,) seconds from the first epoch
    sat_ecef_m: np.ndarray  # (E, N, 3) satellite at transmission, ECEF of that time
    pr_m: np.ndarray  # (E, N) corrected pseudorange
    mask: np.ndarray  # (E, N) real measurements
    cn0_dbhz: np.ndarray  # (E, N) NaN where not reported
    sigma_m: np.ndarray  # (E, N) the error model's σ (the estimator's first guess)
    clock_index: np.ndarray  # (E, N) receiver-clock group
    sv: np.ndarray  # (E, N) measurement labels ('' for empty slots)
    origin_ecef_m: np.ndarray  # (3,) the frame's origin (the first fix)
    ecef2enu: np.ndarray  # (3, 3) rotation, rows east, north, up
    fix_enu_m: np.ndarray  # (E, 3) the snapshot fixes (NaN where none): the start and the initial heading only
    speed_mps: np.ndarray  # (E,) mean odometer speed over the interval ending at each epoch (NaN: none)
    yaw_rate_radps: np.ndarray  # (E,) mean yaw rate (counter-clockwise positive) over that interval (NaN: none)
    forward_m: np.ndarray  # (E,) distance driven forward over that interval, in the frame of its start heading (NaN: none)
    left_m: np.ndarray  # (E,) and to the left

    @cached_property
    def elev_deg(self) -> np.ndarray:
        """(E, N) each satellite's elevation (deg) seen from the frame's origin (made when first asked: only a log
        whose C/N0 tells nothing needs it)."""
        los = self.sat_ecef_m - self.origin_ecef_m
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.degrees(np.arcsin(np.clip((los @ self.ecef2enu[2]) / np.linalg.norm(los, axis=-1), -1.0, 1.0)))

    @cached_property
    def n_clocks(self) -> int:
        return int(self.clock_index[self.mask].max(initial=0)) + 1

    @cached_property
    def kernel_arrays(self) -> tuple:
        """The arrays the compiled pass reads, made once (C-contiguous; the mask as bytes, the clock groups as int64
        with 0 in empty slots): t, satellites, pseudoranges, mask, clocks, speed, yaw rate, forward, left, origin,
        rotation."""
        def c64(a):
            return np.ascontiguousarray(a, np.float64)

        clock = np.ascontiguousarray(np.where(self.mask, self.clock_index, 0), np.int64)
        return (c64(self.t_s), c64(self.sat_ecef_m), c64(self.pr_m), np.ascontiguousarray(self.mask, np.uint8), clock,
                c64(self.speed_mps), c64(self.yaw_rate_radps), c64(self.forward_m), c64(self.left_m),
                c64(self.origin_ecef_m), c64(self.ecef2enu))  # fmt: skip

    @cached_property
    def missing_odometry(self) -> np.ndarray:
        """(E,) the intervals (each ending at its epoch; the first epoch's none) without odometry, as the pass reads
        them: speed, yaw rate, forward or left not a number."""
        present = np.isfinite(self.speed_mps) & np.isfinite(self.yaw_rate_radps) & np.isfinite(self.forward_m) & np.isfinite(self.left_m)
        missing = ~present
        missing[:1] = False
        return missing

    @property
    def has_odometry(self) -> bool:
        """Odometry over at least half of the log's intervals."""
        return has_odometry(self.speed_mps)

    def enu2geodetic(self, enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Latitude, longitude (deg) and height (m) of east-north-up points (E, 3) of this frame."""
        from tollcli.geodesy import ecef2geodetic

        ecef = self.origin_ecef_m + enu_m @ self.ecef2enu
        return ecef2geodetic(ecef[:, 0], ecef[:, 1], ecef[:, 2])


def has_odometry(speed_mps: np.ndarray) -> bool:
    """Odometry over at least half of a log's intervals (``speed_mps``: per epoch, the interval ending there)."""
    return bool(speed_mps.size > 1 and np.isfinite(speed_mps[1:]).mean() >= 0.5)


def has_pseudoranges(meas: Measurements) -> bool:
    """The measurements carry what the estimator needs (a pseudorange log's)."""
    return meas.sat_ecef_m is not None and meas.pr_m is not None and meas.clock_index is not None


def trajectory_inputs(epochs: pd.DataFrame, meas: Measurements) -> TrajectoryInputs:
    """The estimator's inputs from a pseudorange log's epoch table and measurements (``has_pseudoranges``)."""
    t = _seconds(epochs["time_utc"])
    lat, lon, h = (epochs[c].to_numpy(float) for c in ("lat_deg", "lon_deg", "height_m"))
    fixed = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h))
    first = int(fixed[0]) if fixed.size else 0
    origin = np.asarray(geodetic2ecef(lat[first], lon[first], h[first]), float).ravel()
    rot = np.asarray(enu_rotation(lat[first], lon[first]), float).reshape(3, 3)
    ecef = np.stack([np.asarray(a, float) for a in geodetic2ecef(lat, lon, h)], axis=-1)
    fix_enu = (ecef - origin) @ rot.T
    speed = epochs["odometer_speed_mps"].to_numpy(float) if "odometer_speed_mps" in epochs else np.full(t.size, np.nan)
    yaw = epochs["yaw_rate_radps"].to_numpy(float) if "yaw_rate_radps" in epochs else np.full(t.size, np.nan)
    forward = epochs["odometer_forward_m"].to_numpy(float) if "odometer_forward_m" in epochs else speed * np.diff(t, prepend=np.nan)
    left = epochs["odometer_left_m"].to_numpy(float) if "odometer_left_m" in epochs else np.where(np.isfinite(forward), 0.0, np.nan)
    if np.isfinite(forward).any():  # odometry the fixes contradict is no odometry (the estimator then wanders there)
        bad = implausible_odometry(t, fix_enu[:, :2], forward)
        speed, yaw, forward, left = (np.where(bad, np.nan, a) for a in (speed, yaw, forward, left))
    cn0 = meas.cn0_dbhz if meas.cn0_dbhz is not None else np.full(meas.mask.shape, np.nan)
    return TrajectoryInputs(t, meas.sat_ecef_m, meas.pr_m, meas.mask & np.isfinite(meas.pr_m), cn0, meas.sigma_m,
                            meas.clock_index, meas.sv, origin, rot, fix_enu, speed, yaw, forward, left)  # fmt: skip


def _seconds(time_utc: pd.Series) -> np.ndarray:
    ns = pd.DatetimeIndex(time_utc).as_unit("ns").asi8.astype(np.int64)
    return (ns - ns[0]) / 1e9 if ns.size else np.zeros(0)
