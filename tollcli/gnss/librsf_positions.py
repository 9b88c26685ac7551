"""WLS positions and RAIM measurements from a libRSF log (smartLoc: pseudoranges already corrected).

The file gives, per satellite-epoch, a pseudorange with the satellite clock and the atmosphere removed, its
variance, the satellite's ECEF position at transmission, elevation and C/N0 (:mod:`tollcli.readers.librsf`).
The position is the iterated, Sagnac-corrected WLS of :mod:`tollcli.gnss.pseudorange_wls` with one
receiver clock per constellation, batched over epochs; the odometry's forward speed is the epoch's
``speed_mps`` (the vehicle's own wheel speed, nearest in time).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.gnss.odometry import interval_displacement, interval_odometry
from tollcli.gnss.measurements import Measurements, pad, slots, sv_labels
from tollcli.gnss.pseudorange_wls import final_geometry, solvable, solve_positions
from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.readers.librsf import LibrsfLog, librsf_times
from tollcli.times import nearest_index

GALILEO_ID0 = 300  # smartLoc numbers Galileo satellites 300 + PRN


def librsf_epochs(log: LibrsfLog, sigma_model: str = "nominal", sigma_m: float = 5.0,
                  nominal: NominalModel | None = None) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """WLS position per epoch (an epoch table) and the RAIM measurements at that position."""
    d = log.pseudoranges
    if d.empty:
        raise DataError("no pseudorange3 line: a libRSF ground-truth file is a --truth, not a log")
    t_key = np.round(d["t_s"].to_numpy(float) * 1e3).astype(np.int64)
    epoch_ms = bridged_epochs(np.unique(t_key), np.round(log.odometry["t_s"].to_numpy(float) * 1e3).astype(np.int64))
    row = np.searchsorted(epoch_ms, t_key)
    order = np.argsort(row, kind="stable")
    d, row = d.iloc[order], row[order]
    n_epochs = epoch_ms.size
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)
    mask = pad(np.ones(len(d), bool), row, slot, shape, False)
    sat = np.stack([pad(d[c].to_numpy(float), row, slot, shape, 0.0) for c in ("x_sv_m", "y_sv_m", "z_sv_m")], -1)
    pr = pad(d["pr_m"].to_numpy(float), row, slot, shape, 0.0)
    var = d["pr_var_m2"].to_numpy(float)
    unc = pad(np.sqrt(np.where(var > 0, var, np.nan)), row, slot, shape, np.nan)
    cn0 = pad(d["cn0_dbhz"].to_numpy(float), row, slot, shape, np.nan)
    sat_id = d["sat"].to_numpy(np.int64)
    galileo = sat_id >= GALILEO_ID0
    const_rows = np.where(galileo, "Galileo", "GPS").astype(object)
    const = pad(const_rows, row, slot, shape, "")
    labels = pad(sv_labels(const_rows, np.where(galileo, sat_id - GALILEO_ID0, sat_id)), row, slot, shape, "")
    clock_index = pad(galileo.astype(np.int64), row, slot, shape, 0)

    sigma_iter = np.where(mask, np.where(np.isfinite(unc), unc, sigma_m), np.nan)
    x = solve_positions(sat, pr, mask, sigma_iter, clock_index=clock_index)
    g = final_geometry(sat, pr, mask, x, clock_index=clock_index)
    sigma = np.where(mask, sigma_for(sigma_model, elev_deg=g["elev_deg"], cn0_dbhz=cn0, constellation=const,
                                     lat_deg=g["lat_deg"][:, None], lon_deg=g["lon_deg"][:, None], sigma_input_m=unc,
                                     sigma_const_m=sigma_m, nominal=nominal), np.nan)  # fmt: skip
    ok = solvable(mask, clock_index)
    epochs = pd.DataFrame(
        {
            "epoch": np.arange(n_epochs, dtype=np.int64),
            "time_utc": librsf_times(epoch_ms / 1e3),
            "lat_deg": np.where(ok, g["lat_deg"], np.nan),
            "lon_deg": np.where(ok, g["lon_deg"], np.nan),
            "height_m": np.where(ok, g["height_m"], np.nan),
            "clock_bias_m": np.where(ok, x[:, 3], np.nan),
            "n_measurements": mask.sum(axis=1).astype(np.int16),
            "speed_mps": _odometry_speed(log.odometry, epoch_ms),
            **_interval_odometry(log.odometry, epoch_ms),
        }
    )
    epochs.attrs["skipped_lines"] = log.malformed  # malformed lines the reader passed over
    meas = Measurements(g["H"], sigma, mask, labels, dy_m=g["dy_m"], cn0_dbhz=cn0,
                        test_stat_source=np.full(n_epochs, "pseudorange", dtype=object), sat_ecef_m=sat, pr_m=g["pr_m"],
                        clock_index=g["clock_index"])  # fmt: skip
    return epochs, meas


def bridged_epochs(epoch_ms: np.ndarray, odometry_ms: np.ndarray) -> np.ndarray:
    """The pseudorange epochs (ms), and in every gap longer than twice their usual interval (a GNSS outage: a tunnel,
    jamming, an underpass) the odometry's times at that interval: epochs without a satellite, which the trajectory
    estimator carries through on the odometry (a snapshot has no position there)."""
    if epoch_ms.size < 2 or odometry_ms.size == 0:
        return epoch_ms
    step = float(np.median(np.diff(epoch_ms)))
    extra = []
    for g in np.flatnonzero(np.diff(epoch_ms) > 2 * step):  # (outages are few: a loop over them, not over epochs)
        lo, hi = epoch_ms[g], epoch_ms[g + 1]
        inside = odometry_ms[(odometry_ms >= lo + step) & (odometry_ms <= hi - step / 2)]
        last = lo
        for t in inside.tolist():
            if t - last >= step * 0.999:
                extra.append(t)
                last = t
    return np.union1d(epoch_ms, np.asarray(extra, np.int64)) if extra else epoch_ms


def _interval_odometry(odometry: pd.DataFrame, epoch_ms: np.ndarray) -> dict[str, np.ndarray]:
    """The odometer's mean speed (m/s) and yaw rate (rad/s) over the interval ending at each epoch, and the distance
    driven forward and to the left over it (m, in the frame of the heading at its start; NaN: none)."""
    if odometry.empty:
        nan = np.full(epoch_ms.size, np.nan)
        return {"odometer_speed_mps": nan, "yaw_rate_radps": nan.copy(), "odometer_forward_m": nan.copy(), "odometer_left_m": nan.copy()}
    samples = (odometry["t_s"].to_numpy(float), odometry["vx_mps"].to_numpy(float), odometry["wz_radps"].to_numpy(float), epoch_ms / 1e3)
    speed, yaw = interval_odometry(*samples)
    forward, left = interval_displacement(*samples)
    return {"odometer_speed_mps": speed, "yaw_rate_radps": yaw, "odometer_forward_m": forward, "odometer_left_m": left}


def _odometry_speed(odometry: pd.DataFrame, epoch_ms: np.ndarray) -> np.ndarray:
    """The odometer's forward speed (m/s) nearest each epoch (within 0.5 s), NaN without one."""
    if odometry.empty:
        return np.full(epoch_ms.size, np.nan)
    k, gap = nearest_index(np.round(odometry["t_s"].to_numpy(float) * 1e3).astype(np.int64), epoch_ms)
    return np.where(gap <= 500, odometry["vx_mps"].to_numpy(float)[k], np.nan)
