"""Speed integrity (Binjammaz 2015 §4.2.2, ALGORITHMS.md §6), vectorized over epochs.

The check **vetoes a position only on evidence of a fault**: the receiver's Doppler velocity and the
positions disagree. A slow, stopped, accelerating or turning vehicle is no such evidence: there the check
says why it could not confirm the position and leaves it to the RAIM's verdict.

Over a window of ``window_s`` seconds (10 s: N intervals at the log's rate, N = 10 at 1 Hz, 200 at 20 Hz),
with trapezoidal averages (eqs. 4.5, 4.8: (½x₀ + x₁ + … + x_{N−1} + ½x_N)/N):

* ``mase_mps``: the average SDOP — the receiver's Doppler speed accuracy. Raw-measurement inputs give
  it per epoch (``speed_doppler_sigma_mps``, the 1σ of the Doppler WLS speed of
  :mod:`tollcli.gnss.doppler_velocity`; ``speed_sigma_source`` ``doppler_wls``); standard NMEA carries
  no SDOP: a configured value is used and ``speed_sigma_source`` says so (``configured``);
* ``speed_error_mps`` = MASE/√N₁, N₁ the window's whole seconds (eq. 4.6; samples closer than a second are
  not independent);
* ``speed_doppler_avg_mps``: the average Doppler speed (RMC/VTG speed over ground) (eq. 4.8);
* the thesis's availability test: MASE ≥ 3σ, σ the standard error of the window's Doppler samples around
  their straight-line trend (so that steady acceleration is not noise) divided by √(N + 1);
* **the consistency test** a log processor can make: the positions' displacement over the window against the
  one the reported velocity gives, dead-reckoned (speed over ground along the course, trapezoid per
  interval): ``speed_mismatch_m`` = |Δp − Δp_Doppler| must stay within ``speed_tolerance_m`` =
  k·√((speed_error·T)² + σ_h,start² + σ_h,end²) + the length of the intervals without a course (any direction:
  the test is then one-sided, the positions may not have moved further than the speed allows) + the turn term
  Σ L_i·(1 − cos(Δc_i/2)) (a bend between two samples, L_i the interval's length, Δc_i its course change;
  a corner bounds an arc), σ_h the horizontal position σ (GST's major axis, else ``position_sigma_m``), k = 3.72 =
  √(−2 ln 10⁻³): without a fault a 2-D mismatch that far out has probability 10⁻³.
  The displacement, not the path: a bend, a U-turn or a stop do not disagree with the Doppler velocity.

``speed_status``: ``inconsistent`` (the test fails: the positions are not where the reported velocity takes
them — a position or speed fault: **the only veto**), ``ok`` (the test passes at speed ≥ ``min_speed_mps``
with the Doppler available: the check confirms the position), and, not checked, the position left to the
RAIM: ``low_speed`` (below 2 m/s the Doppler speed and course are unreliable, the thesis's low-speed rule: a
consistent window confirms nothing), ``unavailable`` (MASE < 3σ: the samples scatter more than the receiver's
accuracy), ``no_data`` (window incomplete: the first seconds of a log or after a gap, a missing speed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.io.columns import text_of_codes

SPEED_STATUSES = ("ok", "low_speed", "unavailable", "inconsistent", "no_data")
#: the speed verdict that vetoes a position (evidence of a fault); every other one confirms or leaves it to the RAIM
SPEED_FAULTS = ("inconsistent",)
#: the statuses under which the check confirmed nothing: why it could not
SPEED_NOT_CHECKED = ("low_speed", "unavailable", "no_data")
_CODE = {status: k for k, status in enumerate(SPEED_STATUSES)}


#: what each speed verdict tells the reader of an invoice (``speed_`` + status)
SPEED_STATUS_MEANINGS = {
    "speed_no_data": ("not checked: the speed check needs a full window of {w:g} s at a regular rate, each epoch "
                      "with a speed over ground and a position (the first {w:g} s of a log, epochs next to a gap "
                      "and epochs without a speed have none); the RAIM's verdict stands"),
    "speed_low_speed": ("not checked: the vehicle was stationary or slower than {v:g} m/s, where the Doppler speed and "
                        "course are unreliable (the thesis's low-speed rule); the positions agreed with the speed, and "
                        "the RAIM's verdict stands"),
    "speed_unavailable": ("not checked: the Doppler speed's accuracy (MASE) is below 3 sigma of its own samples (no "
                          "speed integrity in the thesis's sense); the positions agreed with the speed, and the RAIM's "
                          "verdict stands"),
    "speed_inconsistent": ("the positions are not where the reported (Doppler) velocity takes them over the window: a "
                           "position or speed fault; the position is not charged on"),
}  # fmt: skip


def speed_status_notes(seen: set[str], duration_s: float | None, step_s: float | None, params: "SpeedParams") -> dict[str, str]:
    """Notes for the speed verdicts an invoice shows; a log shorter than the speed window says so."""
    w = params.window_s
    notes = {k: v.format(w=w, v=params.min_speed_mps) for k, v in SPEED_STATUS_MEANINGS.items() if k in seen}
    if "speed_no_data" in notes and duration_s is not None and step_s and duration_s < w:
        notes["speed_no_data"] = (f"log shorter than the speed window: {duration_s:g} s of epochs {step_s:g} s apart, the "
                                  f"speed check needs {w:g} s, so it checked no position; the RAIM's verdict stands")  # fmt: skip
    return notes


@dataclass(frozen=True)
class SpeedParams:
    window_s: float = 10.0  # the window (Chalko's 10-second averages): N = window_s / the log's epoch interval
    sdop_mps: float = 0.1  # configured Doppler speed accuracy where the log has none
    position_sigma_m: float = 5.0  # horizontal position σ where the log has no GST
    min_speed_mps: float = 2.0
    k_sigma: float = 3.0  # the thesis's availability test, MASE ≥ 3σ
    k_mismatch: float = 3.72  # √(−2 ln 10⁻³): a 2-D mismatch this many σ out has probability 10⁻³ without a fault

    def intervals(self, step_s: float | None) -> int:
        """N: the window's epoch intervals at an epoch interval of ``step_s`` (10 at 1 Hz; 10 without a rate)."""
        if step_s is None or not np.isfinite(step_s) or step_s <= 0:
            return int(round(self.window_s))
        return max(1, int(round(self.window_s / step_s)))


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
    """Per-epoch speed-integrity columns for an epoch table (``speed_mps``, ``course_deg`` where logged,
    ``lat_deg``/``lon_deg``, time; module docstring).

    A window is regular when it spans N epoch intervals; ``step_s`` is that interval (default
    :func:`nominal_step_s` of the table; a log read in chunks gives the one of its first chunk).
    """
    from tollcli.times import epoch_seconds

    m = len(epochs)
    nan = np.full(m, np.nan)
    v = epochs["speed_mps"].to_numpy(float) if "speed_mps" in epochs else nan
    course = epochs["course_deg"].to_numpy(float) if "course_deg" in epochs else nan
    t = epoch_seconds(epochs)
    lat = epochs["lat_deg"].to_numpy(float)
    lon = epochs["lon_deg"].to_numpy(float)
    step = (nominal_step_s(t) if m > 1 else np.nan) if step_s is None else step_s
    n = params.intervals(step)
    given = epochs["speed_doppler_sigma_mps"].to_numpy(float) if "speed_doppler_sigma_mps" in epochs else nan
    from_doppler = np.isfinite(given) & (given > 0)
    mase = trapezoid_average(np.where(from_doppler, given, params.sdop_mps), n)
    speed_error = mase / np.sqrt(max(1, min(n, int(params.window_s))))
    avg = trapezoid_average(v, n)
    sigma = detrended_standard_error(v, n)
    sigma_h = epochs["sigma_major_m"].to_numpy(float) if "sigma_major_m" in epochs else nan
    sigma_h = np.where(np.isfinite(sigma_h) & (sigma_h > 0), sigma_h, params.position_sigma_m)
    w = dead_reckoned_window(t, lat, lon, v, course, n)
    s0 = np.maximum(np.arange(m) - n, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        span = w["span_s"]
        mismatch = np.hypot(w["position_e_m"] - w["doppler_e_m"], w["position_n_m"] - w["doppler_n_m"])
        tol = (params.k_mismatch * np.sqrt((speed_error * span) ** 2 + sigma_h[s0] ** 2 + sigma_h**2)
               + w["no_course_m"] + w["turn_m"])  # fmt: skip
        regular = np.abs(span - n * step) < max(0.5, 0.5 * step) if m > 1 and np.isfinite(step) else np.zeros(m, bool)
        pos_speed = np.hypot(w["position_e_m"], w["position_n_m"]) / span
        have = np.isfinite(avg) & np.isfinite(mismatch) & np.isfinite(tol) & regular
        inconsistent = have & (mismatch > tol)
        passed = have & ~inconsistent
    status = np.full(m, _CODE["no_data"], np.int8)  # codes into SPEED_STATUSES; each later rule overrides an earlier
    status[passed] = _CODE["ok"]
    with np.errstate(invalid="ignore"):
        status[passed & ~(mase >= params.k_sigma * sigma)] = _CODE["unavailable"]
        status[passed & (avg < params.min_speed_mps)] = _CODE["low_speed"]
    status[inconsistent] = _CODE["inconsistent"]
    return pd.DataFrame({
        "speed_doppler_avg_mps": avg, "speed_position_mps": pos_speed, "speed_error_mps": speed_error,
        "mase_mps": mase, "speed_sigma_mps": sigma, "speed_mismatch_m": mismatch, "speed_tolerance_m": tol,
        "speed_sigma_source": text_of_codes(from_doppler.astype(np.int8), ("configured", "doppler_wls")),
        "speed_status": text_of_codes(status, SPEED_STATUSES),
    })  # fmt: skip


def dead_reckoned_window(t_s: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, speed_mps: np.ndarray,
                         course_deg: np.ndarray, n: int) -> dict[str, np.ndarray]:  # fmt: skip
    """Over the n intervals ending at each epoch: the positions' displacement and the reported velocity's.

    Per interval i−1 → i: length L = ½(v_{i−1} + v_i)·Δt along the mean of the two courses; an interval
    without both courses adds its length to ``no_course_m`` instead (its direction is unknown), and one with
    both adds L·(1 − cos(Δc/2)) to ``turn_m`` (how far a bend or a corner between the samples can put the
    end from the mean course). Returns ``span_s``, ``position_e_m``/``position_n_m`` (last minus first
    position), ``doppler_e_m``/``doppler_n_m``, ``no_course_m``, ``turn_m``: NaN before the n-th epoch and
    wherever a speed, a time or a position of the window is missing.
    """
    from tollcli.geodesy import geodetic2enu_shift

    m = t_s.size
    out = {k: np.full(m, np.nan) for k in ("span_s", "position_e_m", "position_n_m", "doppler_e_m", "doppler_n_m",
                                             "no_course_m", "turn_m")}  # fmt: skip
    if m <= n:
        return out
    dt = np.diff(t_s)
    length = 0.5 * (speed_mps[:-1] + speed_mps[1:]) * dt
    rad = np.radians(course_deg)
    se, ce = np.sin(rad[:-1]) + np.sin(rad[1:]), np.cos(rad[:-1]) + np.cos(rad[1:])
    norm = np.hypot(se, ce)
    with np.errstate(invalid="ignore", divide="ignore"):
        ue, un = se / norm, ce / norm
        half_turn = np.radians(np.abs((course_deg[1:] - course_deg[:-1] + 180.0) % 360.0 - 180.0)) / 2.0
    has_course = np.isfinite(ue) & np.isfinite(un) & (norm > 1e-9)
    good = np.isfinite(length) & (dt > 0) & np.isfinite(lat_deg[1:]) & np.isfinite(lat_deg[:-1])
    end = np.arange(n, m)
    bad = _interval_sums((~good).astype(float), n)
    with np.errstate(invalid="ignore"):
        sums = {
            "doppler_e_m": _interval_sums(np.where(good & has_course, length * ue, 0.0), n),
            "doppler_n_m": _interval_sums(np.where(good & has_course, length * un, 0.0), n),
            "no_course_m": _interval_sums(np.where(good & ~has_course, np.abs(length), 0.0), n),
            "turn_m": _interval_sums(np.where(good & has_course, np.abs(length) * (1.0 - np.cos(half_turn)), 0.0), n),
        }
    ok = bad == 0
    pe, pn = geodetic2enu_shift(lat_deg[end - n], lon_deg[end - n], lat_deg[end], lon_deg[end])
    out["span_s"][end] = np.where(ok, t_s[end] - t_s[end - n], np.nan)
    out["position_e_m"][end] = np.where(ok, pe, np.nan)
    out["position_n_m"][end] = np.where(ok, pn, np.nan)
    for k, x in sums.items():
        out[k][end] = np.where(ok, x, np.nan)
    return out


def _interval_sums(x: np.ndarray, n: int) -> np.ndarray:
    """Σ of the n interval values (x[i] for interval i → i + 1) ending at each epoch n … len(x)."""
    c = np.concatenate([[0.0], np.cumsum(x)])
    end = np.arange(n, x.size + 1)
    return c[end] - c[end - n]
