"""Speed integrity (Binjammaz 2015 §4.2.2, ALGORITHMS.md §6), vectorized over epochs.

Over a window of N intervals (N + 1 samples at a regular rate), with trapezoidal averages
(eqs. 4.5, 4.8: (½x₀ + x₁ + … + x_{N−1} + ½x_N)/N):

* ``mase_mps``: the average SDOP — the receiver's Doppler speed accuracy. Raw-measurement inputs give
  it per epoch (``speed_doppler_sigma_mps``, the 1σ of the Doppler WLS speed of
  :mod:`tollcli.gnss.doppler_velocity`; ``speed_sigma_source`` ``doppler_wls``); standard NMEA carries
  no SDOP: a configured value is used and ``speed_sigma_source`` says so (``configured``);
* ``speed_error_mps`` = MASE/√N (eq. 4.6);
* ``speed_doppler_avg_mps``: the average Doppler speed (RMC/VTG speed over ground) (eq. 4.8);
* the thesis's test: integrity available iff MASE ≥ 3σ, σ the standard error of the window's Doppler
  samples. The thesis does not define σ further; here it is the standard deviation of the samples
  around their straight-line trend (so that steady acceleration is not noise) divided by √(N + 1);
* the cross-check a log processor can make: the average Doppler speed against the speed from the
  positions (chord of the window / its duration), within 3·√(speed_error² + σ_pos²), σ_pos = √2·σ_h/T
  with σ_h the horizontal position σ (GST's major axis, else ``position_sigma_m``);
* below ``min_speed_mps`` (2 m/s) Doppler speed and heading are unreliable (the thesis's low-speed rule).

``speed_status``: ``ok``, ``low_speed``, ``unavailable`` (MASE < 3σ), ``inconsistent`` (the
cross-check fails: the Doppler speed is not the speed the positions show), ``no_data`` (window
incomplete or without speeds/positions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

SPEED_STATUSES = ("ok", "low_speed", "unavailable", "inconsistent", "no_data")


#: what each speed verdict tells the reader of an invoice (as the position's status, ``speed_`` + status)
SPEED_STATUS_MEANINGS = {
    "speed_no_data": ("the speed check needs a full window of {n} intervals ({n1} epochs) at a regular rate, each with "
                      "a speed over ground and a position: the first {n} epochs of a log, epochs next to a gap and "
                      "epochs without a speed have none, and are not charged on"),
    "speed_low_speed": ("the vehicle was stationary or slower than {v:g} m/s: below that the Doppler speed and heading "
                        "are unreliable (the thesis's low-speed rule), and the position is not charged on"),
    "speed_unavailable": "the Doppler speed's accuracy (MASE) is below 3 sigma of its own samples: no speed integrity",
    "speed_inconsistent": "the Doppler speed is not the speed the positions show over the window (a position or speed fault)",
}  # fmt: skip


def speed_status_notes(seen: set[str], duration_s: float | None, step_s: float | None, params: "SpeedParams") -> dict[str, str]:
    """Notes for the speed verdicts an invoice shows; a log shorter than the speed window says so."""
    n = params.window_intervals
    notes = {k: v.format(n=n, n1=n + 1, v=params.min_speed_mps) for k, v in SPEED_STATUS_MEANINGS.items() if k in seen}
    if "speed_no_data" in notes and duration_s is not None and step_s and duration_s < n * step_s:
        notes["speed_no_data"] = (f"log shorter than the speed window: {duration_s:g} s of epochs {step_s:g} s apart, the "
                                  f"speed check needs {n * step_s:g} s ({n} intervals), so no position could pass it. "
                                  + notes["speed_no_data"][0].upper() + notes["speed_no_data"][1:])  # fmt: skip
    return notes


@dataclass(frozen=True)
class SpeedParams:
    window_intervals: int = 10  # N (Chalko's 10-second averages)
    sdop_mps: float = 0.1  # configured Doppler speed accuracy where the log has none
    position_sigma_m: float = 5.0  # horizontal position σ where the log has no GST
    min_speed_mps: float = 2.0
    k_sigma: float = 3.0


def trapezoid_average(x: np.ndarray, n: int) -> np.ndarray:
    """(½x₀ + x₁ + … + x_{n−1} + ½x_n)/n over the n + 1 samples ending at each index (NaN before)."""
    x = np.asarray(x, dtype=float)
    out = np.full(x.shape, np.nan)
    if x.size <= n:
        return out
    end = np.arange(n, x.size)
    inner = _window_sums(x, n)[n:]  # x_{e−n} … x_e (NaN where one of them is missing)
    out[n:] = (inner - 0.5 * (x[end - n] + x[end])) / n
    return out


def _window_sums(x: np.ndarray, n: int) -> np.ndarray:
    """Σ of the n + 1 samples ending at each index; NaN before the first full window and for every
    window holding a missing (non-finite) sample — and only those: a gap touches the windows it is in."""
    x = np.asarray(x, dtype=float)
    missing = ~np.isfinite(x)
    c = np.concatenate([[0.0], np.cumsum(np.where(missing, 0.0, x))])
    out = np.full(x.shape, np.nan)
    if x.size > n:
        end = np.arange(n, x.size)
        sums = c[end + 1] - c[end - n]
        if missing.any():
            k = np.concatenate([[0], np.cumsum(missing)])
            sums = np.where(k[end + 1] - k[end - n] > 0, np.nan, sums)
        out[n:] = sums
    return out


def detrended_standard_error(v: np.ndarray, n: int) -> np.ndarray:
    """Std of the n + 1 samples around their least-squares line, over √(n + 1) (NaN before the first full window)."""
    v = np.asarray(v, dtype=float)
    m = n + 1
    j = np.arange(v.size, dtype=float)
    centre = j - (n / 2.0)  # local abscissa is j − (window start + n/2): sums of it are exact below
    sv, svv = _window_sums(v, n), _window_sums(v * v, n)
    sjv = _window_sums(j * v, n)
    # with local t = j − (e − n/2), Σt = 0, Σt² = n(n+1)(n+2)/12, Σtv = Σjv − (e − n/2)Σv
    stt = n * (n + 1) * (n + 2) / 12.0
    stv = sjv - centre * sv
    ss = svv - sv * sv / m - stv * stv / stt
    with np.errstate(invalid="ignore"):
        sd = np.sqrt(np.maximum(ss, 0.0) / max(m - 2, 1))
    return sd / np.sqrt(m)


def nominal_step_s(t_s: np.ndarray) -> float:
    """The log's epoch interval: the median step between epoch times (s; NaN with fewer than two)."""
    return float(np.nanmedian(np.diff(t_s))) if len(t_s) > 1 and np.isfinite(np.diff(t_s)).any() else float("nan")


def speed_integrity(epochs: pd.DataFrame, params: SpeedParams = SpeedParams(), step_s: float | None = None) -> pd.DataFrame:
    """Per-epoch speed-integrity columns for an epoch table (``speed_mps``, ``lat_deg``/``lon_deg``, time).

    A window is regular when it spans N epoch intervals; ``step_s`` is that interval (default
    :func:`nominal_step_s` of the table; a log read in chunks gives the one of its first chunk).
    """
    from tollcli.geodesy import great_circle_distance_m
    from tollcli.times import epoch_seconds

    n = params.window_intervals
    v = epochs["speed_mps"].to_numpy(float) if "speed_mps" in epochs else np.full(len(epochs), np.nan)
    t = epoch_seconds(epochs)
    lat = epochs["lat_deg"].to_numpy(float)
    lon = epochs["lon_deg"].to_numpy(float)
    given = epochs["speed_doppler_sigma_mps"].to_numpy(float) if "speed_doppler_sigma_mps" in epochs else np.full(len(epochs), np.nan)
    from_doppler = np.isfinite(given) & (given > 0)
    sdop = np.where(from_doppler, given, params.sdop_mps)
    mase = trapezoid_average(sdop, n)
    speed_error = mase / np.sqrt(n)
    avg = trapezoid_average(v, n)
    sigma = detrended_standard_error(v, n)
    # the positions' speed: the window's chord over its duration
    start = np.arange(len(epochs)) - n
    ok_start = start >= 0
    s0 = np.where(ok_start, start, 0)
    span = np.where(ok_start, t - t[s0], np.nan)
    chord = np.where(ok_start, great_circle_distance_m(lat[s0], lon[s0], lat, lon), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        pos_speed = chord / span
        sigma_h = epochs["sigma_major_m"].to_numpy(float) if "sigma_major_m" in epochs else np.full(len(epochs), np.nan)
        sigma_h = np.where(np.isfinite(sigma_h) & (sigma_h > 0), sigma_h, params.position_sigma_m)
        sigma_pos = np.sqrt(2.0) * sigma_h / span
        tol = params.k_sigma * np.sqrt(speed_error**2 + sigma_pos**2)
        step = nominal_step_s(t) if step_s is None else step_s
        regular = np.abs(span - n * step) < 0.5 if len(t) > 1 else np.zeros(len(t), bool)
    have = np.isfinite(avg) & np.isfinite(pos_speed) & regular
    status = np.full(len(epochs), "no_data", dtype=object)
    with np.errstate(invalid="ignore"):
        status[have] = "ok"
        status[have & (np.abs(avg - pos_speed) > tol)] = "inconsistent"
        status[have & ~(mase >= params.k_sigma * sigma)] = "unavailable"
        status[have & (avg < params.min_speed_mps)] = "low_speed"
    return pd.DataFrame({
        "speed_doppler_avg_mps": avg, "speed_position_mps": pos_speed, "speed_error_mps": speed_error,
        "mase_mps": mase, "speed_sigma_mps": sigma, "speed_tolerance_mps": tol,
        "speed_sigma_source": pd.array(np.where(from_doppler, "doppler_wls", "configured"), dtype="string"),
        "speed_status": pd.array(status, dtype="string"),
    })  # fmt: skip
