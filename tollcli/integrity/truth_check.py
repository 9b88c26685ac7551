"""Integrity against the truth: position errors, the Stanford diagram's regions, missed detections.

Joins an integrity epoch table (``tollcli integrity`` output: ``time_utc``,
``lat_deg``, ``lon_deg``, ``raim_status``, ``hpl_m``, ``hal_m``, ``p_md``) with a
truth trajectory (``time_utc``, ``lat_deg``, ``lon_deg``) on time, and counts:

* ``positioning_failures``: horizontal error > HAL (whatever the RAIM said);
* ``undetected``: positioning failures the RAIM declared valid — the rate
  ``undetected / positioning_failures`` is what P_MD bounds (per failure, at the
  worst-case bias; smaller biases are detected less often but cause no failure); without a positioning failure
  there is nothing to miss: the rate is null, never a 0/0 printed as 0;
* ``valid`` and ``availability`` (valid / with a position): a method that declares nothing valid misleads nobody
  and charges nothing — the two figures are read together;
* Stanford regions over epochs with a position: ``normal`` (error ≤ HPL ≤ HAL,
  valid), ``misleading`` (HPL < error ≤ HAL, valid), ``hazardous`` (error > HAL,
  valid), ``alarm`` (an alarm — fault_detected, probable_false_alarm —, error ≤ HAL), ``alarm_failure`` (an alarm,
  error > HAL), ``unavailable`` (no alarm and not valid — unavailable, insufficient, unmonitored: no bound or no
  check —, error ≤ HAL), ``unavailable_failure`` (the same, error > HAL).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.geodesy import geodetic2enu
from tollcli.times import nearest_index

VALID_STATUSES = ("valid", "excluded_valid")
#: statuses that are an alarm (the check saw a fault, or probably a false one); every other status that is not valid
#: is a position without a verdict (no bound within the HAL, too few satellites, nothing to check with)
ALARM_STATUSES = ("fault_detected", "probable_false_alarm")


def horizontal_error_m(lat_deg, lon_deg, true_lat_deg, true_lon_deg) -> np.ndarray:
    """Horizontal distance (m) between estimated and true positions (local east-north)."""
    east, north, _ = geodetic2enu(np.asarray(lat_deg, float), np.asarray(lon_deg, float), 0.0, np.asarray(true_lat_deg, float),
                                  np.asarray(true_lon_deg, float), 0.0)  # fmt: skip
    return np.hypot(east, north)


def _times_ms(column: pd.Series, what: str) -> np.ndarray:
    times = pd.to_datetime(column, utc=True, errors="coerce")
    if times.isna().any():
        raise DataError(f"{what}: some time_utc values are missing or unreadable")
    return times.dt.tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64)


def errors_against_truth(epochs: pd.DataFrame, truth: pd.DataFrame, tolerance_s: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Per epoch: the horizontal error against the truth at the nearest time (NaN without one) and whether a truth time matched."""
    t_est = _times_ms(epochs["time_utc"], "epoch table")
    t_tru = _times_ms(truth["time_utc"], "truth")
    if len(t_tru) == 0:
        return np.full(len(epochs), np.nan), np.zeros(len(epochs), bool)
    k, gap_ms = nearest_index(t_tru, t_est)
    matched = gap_ms <= tolerance_s * 1000
    lat = epochs["lat_deg"].to_numpy(float)
    have = matched & np.isfinite(lat)
    err = np.full(len(epochs), np.nan)
    if have.any():
        err[have] = horizontal_error_m(lat[have], epochs["lon_deg"].to_numpy(float)[have],
                                       truth["lat_deg"].to_numpy(float)[k[have]], truth["lon_deg"].to_numpy(float)[k[have]])  # fmt: skip
    return err, matched


def check_against_truth(epochs: pd.DataFrame, truth: pd.DataFrame, tolerance_s: float = 0.05) -> dict:
    """Counts and rates of the module docstring (epochs without a matching truth time are not counted)."""
    for name, table, cols in (("epoch table", epochs, ("time_utc", "lat_deg", "lon_deg", "raim_status", "hpl_m", "hal_m")),
                              ("truth", truth, ("time_utc", "lat_deg", "lon_deg"))):  # fmt: skip
        missing = [c for c in cols if c not in table.columns]
        if missing:
            raise DataError(f"{name}: missing columns {', '.join(missing)}")
    err, matched = errors_against_truth(epochs, truth, tolerance_s)
    have = matched & np.isfinite(err)
    status = epochs["raim_status"].astype(str)
    valid = status.isin(VALID_STATUSES).to_numpy() & have
    alarm = status.isin(ALARM_STATUSES).to_numpy() & have
    unavailable = have & ~valid & ~alarm
    hpl = epochs["hpl_m"].to_numpy(float)
    hal = epochs["hal_m"].to_numpy(float)
    with np.errstate(invalid="ignore"):
        failure = have & (err > hal)
        regions = {
            "normal": int(np.sum(valid & (err <= hpl))),
            "misleading": int(np.sum(valid & (err > hpl) & (err <= hal))),
            "hazardous": int(np.sum(valid & (err > hal))),
            "alarm": int(np.sum(alarm & (err <= hal))),
            "alarm_failure": int(np.sum(alarm & (err > hal))),
            "unavailable": int(np.sum(unavailable & (err <= hal))),
            "unavailable_failure": int(np.sum(unavailable & (err > hal))),
        }
    n_fail = int(failure.sum())
    n_undetected = int(np.sum(failure & valid))
    p_md = float(epochs["p_md"].iloc[0]) if "p_md" in epochs and len(epochs) else float("nan")
    from tollcli.stats import wilson

    low, high = wilson(n_undetected, n_fail)
    return {
        "epochs": len(epochs), "matched": int(matched.sum()), "with_position": int(have.sum()),
        "valid": int(valid.sum()), "availability": float(valid.sum() / have.sum()) if have.any() else None,
        "horizontal_error_m": {"median": _q(err[have], 0.5), "p95": _q(err[have], 0.95), "max": _q(err[have], 1.0)},
        "regions": regions, "positioning_failures": n_fail, "undetected": n_undetected,
        "undetected_rate": n_undetected / n_fail if n_fail else None, "undetected_rate_ci95": [low, high], "p_md": p_md,
    }  # fmt: skip


def _q(values: np.ndarray, q: float) -> float | None:
    return float(np.quantile(values, q)) if values.size else None
