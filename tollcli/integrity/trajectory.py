"""The trajectory of a whole log and its protection level: the city's positioning (``--positioning``).

* ``smoothed`` (after the trip): the robust filter (:mod:`tollcli.integrity.trajectory_filter`) run forward and
  backward over the log; at each epoch the forward posterior and the backward prior (two estimates from disjoint
  measurements, but with correlated errors: reflections last) are combined by **covariance intersection**, which is
  consistent whatever their correlation: P⁻¹ = ω P_f⁻¹ + (1 − ω) P_b⁻¹, ω minimising the horizontal variance;
  near the log's ends, with odometry, the older pass alone (:func:`at_the_ends`, :data:`END_CORRELATIONS`), and the
  fault test's verdict from beyond those ends' windows (:func:`inherited_at_the_ends`);
* ``filtered`` (what an on-board unit could do): the forward pass alone — each position from the measurements up to
  its epoch. Its bound is checked against the whole trip, as only a log processor can: HPL = max(K σ_forward,
  |x_forward − x_smoothed| + HPL_smoothed) (wherever the smoothed bound holds, the forward position is within this),
  and its fault test is the smoothed one's. The forward pass's own bound does not hold when the odometry goes wrong
  (on simulated drives with a 3 % odometer scale step or a 0.02 rad/s gyro bias step: 70–110 misleading epochs).

The noise is the log's own (:mod:`tollcli.integrity.trajectory_noise`): the error model's σ scaled so the median
normalised innovation is χ²₁'s, then :data:`NOISE_ROUNDS` times σ per C/N0 bin from the residuals at the smoothed
trajectory, inflated for their time correlation — each satellite's, or the position's where the satellites' errors
lean together more (the larger). ``filtered`` is calibrated the same way, as an on-board unit is
calibrated on earlier drives: measured at the forward pass's own positions, the residuals carry that pass's errors
(p50 15 m on Berlin) and the noise looks twice as large as it is (the forward pass then valid at HAL 50 m in 65 % of
Berlin's epochs, against 92 % calibrated at the smoothed trajectory; 0 misleading either way).

The protection level is HPL = :data:`K_FUSED` · σ_major of the horizontal covariance. No truth is read here.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from tollcli.integrity.trajectory_filter import MOTION_STATES, START_SPEED_MPS, MotionNoise, PassBuffers, run_pass
from tollcli.integrity.trajectory_inputs import TrajectoryInputs
from tollcli.integrity.trajectory_noise import (
    correlation_inflation,
    correlation_lags,
    noise_bins,
    position_inflation,
    postfit_residuals,
    sigma_by_bin,
)
from tollcli.integrity.trajectory_sweep import sigma_major_m, sweep, swept_whole
from tollcli.stats import median

#: ``auto``: smoothed, with the log's odometry or without (the GNSS-only motion model): on the simulator's city drives
#: without odometry the snapshot RAIM let 65–86 misleading epochs through in 10 000 and the GNSS-only trajectory none,
#: valid at 99.9 % (docs/integrity.md); snapshot where the log cannot carry a trajectory (:func:`with_trajectory`)
POSITIONINGS = ("auto", "smoothed", "filtered", "snapshot")
#: HPL = K_FUSED · σ_major (a Gaussian's two-sided 5σ is 6e-7; the margin covers the heavy tail of city errors)
K_FUSED = 5.0
#: near a log's ends one pass is young: it has seen only the last few correlation times of the log's errors, one
#: reflection however small its covariance says it is. Within this many correlation times of the log's first epoch the
#: position is the backward pass's alone, within as many of its last the forward pass's. On the Berlin drive's 29 parts
#: (``benchmarks/berlin_cuts.py``) the two that start at 120 s start inside a 65 s reflection 30–47 m north of the road:
#: their forward pass followed it, 40 m off with σ_major 7 m, while the backward pass, from the clean end, was 8 m off,
#: and the combination 31 m off with HPL 27 m (193 misleading, 44 hazardous at HAL 30 m); with 1, 2, 3 correlation
#: times 160, 18, 0 misleading (the whole drive: 100 % valid at HAL 30 m, 98 %, 91 %). With odometry only: the odometry
#: carries an old pass's trajectory from far away, so an old pass knows much more than a young one; without, both
#: passes forget at the motion model's pace and the rule only takes away (Berlin without its odometry: 45.5 → 19.9 %
#: valid at HAL 50 m, the parts' misleading epochs 47 → 21)
END_CORRELATIONS = 3.0
#: and the older pass's position there is what it brought from beyond: where the fault test failed (or a pass lost the
#: vehicle) within this many correlation times beyond an end's window, the window fails too (:func:`inherited_at_the_ends`).
#: A pass carries a fault's error long after it: on the simulated drive with a 10 % odometer step, the backward pass was
#: still 13 m off 40 s (6 correlation times) after it had crossed the fault, 26 m off as it left it. On the simulated
#: drives with an odometer or a gyro fault, cut into parts of 130 and 200 s every 23 s (in-process, statuses applied;
#: 132 461 epochs each: docs/integrity.md), hazardous epochs at HAL 50 m: 738 and 28 without, 0 and 0 with 3 or 10; misleading 1 967 and
#: 757 without, 326 and 150 with 3, 326 and 0 with 10. The Berlin drive: whole, no change; its parts lose 0.8 % of their
#: valid epochs (with 3: none)
INHERIT_CORRELATIONS = 10.0
#: rounds of noise estimation from the residuals. One round would save a sweep (0.21 instead of 0.30 s on a simulated
#: 10 000-epoch city drive) but the second is what Berlin needs: with one, its error p50 / p95 7.2 / 15.9 m against
#: 5.8 / 11.9 m, its largest HPE/HPL 0.96 against 0.84, without odometry p95 38.8 against 32.7 m (2026-11-27; the
#: simulated drives barely change)
NOISE_ROUNDS = 2
#: epochs of the window the initial heading is fitted over
HEADING_WINDOW = 300
#: the gyro bias's σ at the start (rad/s): a consumer MEMS gyro's turn-on bias, up to ~0.3 °/s
GYRO_BIAS0_RADPS = 0.005
#: the receiver clock drift's σ at the start (m/s): a receiver's TCXO may be 1 ppm off (300 m/s; a u-blox walk's is
#: −60 m/s) — with 10 m/s the first epochs' clocks ran off their prior and a pass started "lost"
DRIFT0_MPS = 300.0
#: the σ of a measurement the error model gives none (m)
FALLBACK_SIGMA_M = 30.0
#: the median of χ²₁
CHI2_1_MEDIAN = 0.4549364231195724
#: C/N0 (dB-Hz) below which a pseudorange is left out of the trajectory (a C/N0 not reported keeps it): a city's weak
#: signals are mostly reflections, late by tens of metres for tens of seconds — a bias that down-weighting does not
#: take out. Chosen on the simulator's city and town drives, with and without odometry, as the motion noise was (the
#: mask among none, 25, 30 and 35 dB-Hz with the smallest worst 95th-percentile error, each drive's relative to its
#: best, and no misleading epoch: ``benchmarks/trajectory_settings.py``). The snapshot RAIM keeps every measurement.
MIN_CN0_DBHZ = 30.0


@dataclass
class Trajectory:
    """Per epoch: the ENU position (E, 3), its horizontal covariance (E, 2, 2), σ_major and HPL (m), and how many
    of its measurements the robust loss kept (weight ≥ 0.5) and set aside (of those above the C/N0 mask)."""

    enu_m: np.ndarray
    cov_en_m2: np.ndarray
    sigma_major_m: np.ndarray
    hpl_m: np.ndarray
    n_kept: np.ndarray
    n_set_aside: np.ndarray
    test_stat: np.ndarray  # the fault test's statistic (χ²_dof when fault-free): see :func:`fault_test`
    dof: np.ndarray
    lost: np.ndarray  # epochs within LOST_WINDOW_S of where a pass lost the vehicle: a fault, whatever the test says
    sigma_by_cn0_m: np.ndarray  # the noise table of the last round (per C/N0 bin, or per elevation bin: noise_bins)
    inflation: float  # the correlation factor of the last round
    correlation_s: float  # how long the residuals stay correlated (ρ above trajectory_noise.RHO_CUT): the evidence's independence time
    positioning: str
    odometry: bool


def estimate_trajectory(inp: TrajectoryInputs, positioning: str = "smoothed", noise: MotionNoise = MotionNoise(),
                        min_cn0_dbhz: float = MIN_CN0_DBHZ) -> Trajectory:  # fmt: skip
    """The log's trajectory and protection levels (``positioning``: smoothed or filtered), from the measurements of
    at least ``min_cn0_dbhz`` (or without a C/N0)."""
    if positioning not in ("smoothed", "filtered"):
        raise ValueError(f"positioning {positioning!r}: smoothed or filtered")
    weak = inp.mask & (inp.cn0_dbhz < min_cn0_dbhz)  # NaN (not reported) compares False: kept
    if weak.any():
        inp = replace(inp, mask=inp.mask & ~weak)
    odometry = inp.has_odometry
    m = MOTION_STATES
    sigma = np.where(inp.mask & np.isfinite(inp.sigma_m) & (inp.sigma_m > 0), inp.sigma_m, FALLBACK_SIGMA_M)
    sigma2 = sigma**2
    sigma = None
    start_f = _start(inp, odometry, m, 1)
    # the passes' arrays, the same for every round (each read before the next); a log swept in chunks keeps none
    buffers = PassBuffers() if swept_whole(inp.mask.shape[0]) else None
    with ThreadPoolExecutor(max_workers=1) as pool:  # the first pass (compiled: it lets go of the interpreter) beside
        # what does not depend on it
        first_pass = pool.submit(run_pass, inp, sigma2, 1, *start_f, odometry, noise, keep=(), buffers=buffers)
        start_b = _start(inp, odometry, m, -1)
        sv_code = np.full(inp.mask.shape, -1, np.int32)  # the measurements' labels as numbers, in the labels' order
        sv_code[inp.mask] = pd.factorize(inp.sv[inp.mask], sort=True)[0]
        bins, n_bins, _by = noise_bins(inp.cn0_dbhz, lambda: inp.elev_deg, inp.mask)
        first = first_pass.result()  # its innovations: the error model's scale
        first_pass = None  # (the future holds the pass: let both go once read)
    kept = first.weight >= 0.5
    if kept.any():
        sigma2 = sigma2 * max(1.0, float(median(first.z[kept] ** 2)) / CHI2_1_MEDIAN)
    first = kept = None
    passes = sweep(inp, sigma2, start_f, start_b, odometry, noise, full=NOISE_ROUNDS == 0, buffers=buffers)  # a round reads x and weight only
    table, factor, rho = np.full(1, np.nan), 1.0, np.ones(1)
    for round_ in range(NOISE_ROUNDS):
        res = postfit_residuals(inp, passes.x, m)  # the noise measured at the smoothed trajectory, whichever positioning
        table = sigma_by_bin(res, bins, n_bins, inp.mask)
        kept = inp.mask & (passes.weight >= 0.5)
        smoothed_x = passes.x
        passes = None  # (let go before the next sweep is made)
        z = np.clip(res / table[bins], -5.0, 5.0)
        res = sigma2 = None
        leaning, leaning_rho = 1.0, np.ones(1)
        if round_ == NOISE_ROUNDS - 1:  # the satellites' errors leaning together (in the last round only: the same
            # figures on every drive of benchmarks/integrity_truth.py as in both, for half the cost), found on a second
            # thread beside the correlation (both read z alone; numpy's transforms and sums let go of the interpreter)
            with ThreadPoolExecutor(max_workers=1) as pool:
                leaning_job = pool.submit(position_inflation, z, inp, smoothed_x, kept)
                factor, rho = correlation_inflation(z, sv_code, kept)  # the kept, not the outliers
                leaning, leaning_rho = leaning_job.result()
        else:
            factor, rho = correlation_inflation(z, sv_code, kept)
        if leaning > factor:
            factor = leaning
        if correlation_lags(leaning_rho) > correlation_lags(rho):
            rho = leaning_rho
        z = kept = smoothed_x = None
        white2 = np.where(inp.mask, table[bins] ** 2, FALLBACK_SIGMA_M**2)
        sigma2 = white2 * max(factor, 1.0)
        passes = sweep(inp, sigma2, start_f, start_b, odometry, noise, white2, full=round_ == NOISE_ROUNDS - 1, buffers=buffers)
    step_s = float(np.median(np.diff(inp.t_s))) if inp.t_s.size > 1 else 1.0
    correlation_s = correlation_lags(rho) * step_s
    x, cov = at_the_ends(inp.t_s, passes, END_CORRELATIONS * correlation_s) if odometry else (passes.x, passes.cov_en_m2)
    major = sigma_major_m(cov)
    hpl = K_FUSED * major
    weight = passes.weight
    if positioning == "filtered":  # the forward positions, bounded through the smoothed ones
        hpl = np.maximum(K_FUSED * sigma_major_m(passes.forward_cov_en_m2),
                         np.hypot(*(passes.forward_x[:, :2] - x[:, :2]).T) + hpl)  # fmt: skip
        x, cov, weight = passes.forward_x, passes.forward_cov_en_m2, passes.forward_weight
        major = sigma_major_m(cov)
    n_kept = (inp.mask & (weight >= 0.5)).sum(axis=1)
    test_stat, dof = passes.test_stat, passes.dof
    lost = near(inp.t_s, passes.relocked, LOST_WINDOW_S)
    if odometry:
        test_stat, lost = inherited_at_the_ends(inp.t_s, test_stat, lost, END_CORRELATIONS * correlation_s,
                                                INHERIT_CORRELATIONS * correlation_s)  # fmt: skip
    return Trajectory(x[:, :3], cov, major, hpl, n_kept, inp.mask.sum(axis=1) - n_kept, test_stat, dof, lost, table, factor,
                      correlation_s, positioning, odometry)  # fmt: skip


def at_the_ends(t_s: np.ndarray, passes, end_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The smoothed states (E, S) and horizontal covariances (E, 2, 2) of a full sweep, but within ``end_s`` of the
    log's first epoch the backward pass's alone, and within ``end_s`` of its last the forward pass's (where an epoch is
    within ``end_s`` of both, the combination)."""
    x, cov = passes.x.copy(), passes.cov_en_m2.copy()
    young_forward = t_s - t_s[0] < end_s
    young_backward = t_s[-1] - t_s < end_s
    backward_only = young_forward & ~young_backward
    forward_only = young_backward & ~young_forward
    x[backward_only], cov[backward_only] = passes.backward_x[backward_only], passes.backward_cov_en_m2[backward_only]
    x[forward_only], cov[forward_only] = passes.forward_x[forward_only], passes.forward_cov_en_m2[forward_only]
    return x, cov


def inherited_at_the_ends(t_s: np.ndarray, test_stat: np.ndarray, lost: np.ndarray, end_s: float,
                          beyond_s: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The fault test's statistic (E,) and the lost flags (E,) with each end's window (the epochs within ``end_s`` of the
    log's first or last, where one pass is young and the test has no power: :func:`at_the_ends`) given the largest
    statistic of the ``beyond_s`` seconds beyond it, and lost if any epoch there is: the older pass brings its position
    from there. With odometry every epoch's test has the same degrees of freedom (3), so the largest statistic is the
    most significant. NaN statistics (no test) are passed over."""
    test_stat, lost = test_stat.copy(), lost.copy()
    for since in (t_s - t_s[0], t_s[-1] - t_s):
        window = since < end_s
        beyond = (since >= end_s) & (since < end_s + beyond_s)
        if not window.any() or not beyond.any():
            continue
        worst = np.fmax.reduce(test_stat[beyond])
        if np.isfinite(worst):
            test_stat[window] = np.fmax(test_stat[window], worst)
        lost[window] |= bool(lost[beyond].any())
    return test_stat, lost


#: how long before and after an epoch where a pass lost the vehicle (:mod:`tollcli.integrity.trajectory_filter`)
#: its positions are suspect (s): a pass drifts out for a while before it loses the vehicle (≈ 20 s on the simulated
#: drives with a 0.05 rad/s gyro fault), and the other pass may be inside the same fault
LOST_WINDOW_S = 30.0


def near(t_s: np.ndarray, events: np.ndarray, window_s: float) -> np.ndarray:
    """Epochs within ``window_s`` (s) of an epoch where ``events`` (E,) is true; times ``t_s`` (E,) sorted."""
    at = t_s[events]
    if at.size == 0:
        return np.zeros(t_s.size, bool)
    i = np.searchsorted(at, t_s)
    before = np.abs(t_s - at[np.clip(i - 1, 0, at.size - 1)])
    after = np.abs(at[np.clip(i, 0, at.size - 1)] - t_s)
    return np.minimum(before, after) <= window_s


def _starts(inp: TrajectoryInputs, odometry: bool, m: int):
    """The forward and backward passes' first states and covariances."""
    return _start(inp, odometry, m, 1), _start(inp, odometry, m, -1)


def _start(inp: TrajectoryInputs, odometry: bool, m: int, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """The first state and covariance of the pass in ``direction`` (1 forward, -1 backward)."""
    n_states = m + inp.n_clocks
    fixed = np.flatnonzero(np.isfinite(inp.fix_enu_m).all(axis=1))
    if fixed.size == 0:
        raise ValueError("no snapshot fix to start the trajectory from")
    p = np.zeros((n_states, n_states))
    p[[0, 1, 2], [0, 1, 2]] = 30.0**2
    p[m - 1, m - 1] = DRIFT0_MPS**2  # drift
    p[np.arange(m, n_states), np.arange(m, n_states)] = 100.0**2
    window = fixed[:HEADING_WINDOW] if direction > 0 else fixed[-HEADING_WINDOW:][::-1]
    first = 0 if direction > 0 else inp.t_s.size - 1  # the epoch the pass starts at
    x0 = np.zeros(n_states)
    if odometry:
        psi, start, misfit = _fitted_start(inp, window)
        x0[3], x0[:2] = psi, start
        p[0, 0] = p[1, 1] = max(30.0**2, misfit**2)  # an odometry that does not fit the fixes: a start as uncertain
        p[3, 3] = 0.3**2
        p[4, 4] = GYRO_BIAS0_RADPS**2
    else:
        x0[:2] = inp.fix_enu_m[window[0], :2]
        p[3, 3] = p[4, 4] = 20.0**2  # the velocity
    x0[2] = np.median(inp.fix_enu_m[window[: min(30, window.size)], 2])
    if window[0] != first:  # no fix where the pass starts: the vehicle may have gone far from (and turned since) its first fix
        between = slice(min(first, window[0]) + 1, max(first, window[0]) + 1)
        gone_m = START_SPEED_MPS * abs(float(inp.t_s[window[0]] - inp.t_s[first]))
        p[0, 0] += gone_m**2
        p[1, 1] += gone_m**2
        if odometry:  # the turn the gyro measured between (rad)
            turn = np.abs(np.nan_to_num(inp.yaw_rate_radps[between])) * np.diff(inp.t_s)[between.start - 1 : between.stop - 1]
            p[3, 3] += float(np.sum(turn)) ** 2
    return x0, p


def _fitted_start(inp: TrajectoryInputs, window: np.ndarray) -> tuple[float, np.ndarray, float]:
    """Heading (rad) and east-north position at ``window[0]``: the odometry's dead-reckoned shape over ``window``
    (epochs in the pass's order) rotated and shifted to fit the snapshot fixes best (Cauchy cost, 2° steps); and the
    fit's median distance from the fixes (m: a stuck or wrong odometer fits them badly)."""
    lo, hi = int(window.min()), int(window.max())
    span = np.arange(lo, hi + 1)
    t = inp.t_s[span]
    dt = np.diff(t)
    v = np.nan_to_num(inp.speed_mps[span[1:]])
    w = np.nan_to_num(inp.yaw_rate_radps[span[1:]])
    turn = np.concatenate([[0.0], np.cumsum(-w * dt)])  # heading change since span[0] (clockwise positive)
    psi0 = np.radians(np.arange(0.0, 360.0, 2.0))[:, None]
    # the arc east and north for every start heading ψ₀: sin(ψ₀ + turn) = sin ψ₀ cos turn + cos ψ₀ sin turn, so each
    # is two running sums turned by ψ₀
    along_cos = np.concatenate([[0.0], np.cumsum(v * dt * np.cos(turn[:-1]))])
    along_sin = np.concatenate([[0.0], np.cumsum(v * dt * np.sin(turn[:-1]))])
    de = np.sin(psi0) * along_cos + np.cos(psi0) * along_sin
    dn = np.cos(psi0) * along_cos - np.sin(psi0) * along_sin
    at = window - lo
    fe, fn = inp.fix_enu_m[window, 0], inp.fix_enu_m[window, 1]
    ex, nx = fe[None, :] - de[:, at], fn[None, :] - dn[:, at]
    off_e, off_n = np.median(ex, axis=1), np.median(nx, axis=1)
    ex -= off_e[:, None]
    nx -= off_n[:, None]
    best = int(np.argmin(np.log1p((np.square(ex) + np.square(nx)) / 15.0**2).sum(axis=1)))
    first = at[0]  # window[0]: the pass's first epoch (the span's last for a backward pass)
    heading = float(psi0[best, 0] + turn[first])
    misfit = float(np.median(np.hypot(ex[best], nx[best])))
    return heading, np.array([off_e[best] + de[best, first], off_n[best] + dn[best, first]]), misfit


#: the fewest snapshot fixes a log needs for a trajectory (fewer: its snapshot positions stay)
MIN_FIXES = 10
#: the shortest log a trajectory is estimated for (s), and how many of its errors' correlation times it must last: the
#: noise is measured from the log's own residuals, and a reflection that lasts the whole log looks like no error at all
MIN_DURATION_S = 120.0
DURATION_CORRELATIONS = 5.0


def with_trajectory(epochs, meas, positioning: str):
    """A pseudorange log's epochs placed by the trajectory estimator (``positioning``: smoothed or filtered; snapshot
    leaves them as they are; auto: smoothed), and its
    measurements with the estimator's bound and fault test for the verdicts.

    Returns (epochs, measurements, the positioning used): ``snapshot`` where the log cannot carry a trajectory (no
    satellites and pseudoranges in its measurements, fewer than :data:`MIN_FIXES` snapshot fixes, shorter than
    :data:`MIN_DURATION_S` or than :data:`DURATION_CORRELATIONS` times its errors' correlation time: then
    ``attrs['positioning_note']`` says why). The epoch table
    keeps the snapshot fix as ``snapshot_lat_deg``/``snapshot_lon_deg``; ``lat_deg``/``lon_deg``/``height_m`` become
    the trajectory's, ``sigma_major_m`` its 1σ semi-major axis, and ``positioning`` says which; its attribute
    ``trajectory_correlation_s`` is how long the trajectory's errors stay correlated (positions closer in time are
    not independent evidence).
    """
    from tollcli.integrity.trajectory_inputs import has_pseudoranges, trajectory_inputs

    if positioning == "snapshot" or not has_pseudoranges(meas):
        return epochs, meas, "snapshot"
    if positioning == "auto":
        positioning = "smoothed"
    fixes = int(np.isfinite(epochs["lat_deg"].to_numpy(float)).sum())
    if fixes < MIN_FIXES:
        return _refused(epochs, f"the log has {fixes} snapshot fixes, fewer than the {MIN_FIXES} a trajectory starts from"), meas, "snapshot"
    inp = trajectory_inputs(epochs, meas)
    duration_s = float(inp.t_s[-1] - inp.t_s[0]) if inp.t_s.size else 0.0
    if duration_s < MIN_DURATION_S:
        return _refused(epochs, f"the log lasts {duration_s:.0f} s, less than the {MIN_DURATION_S:.0f} s a trajectory needs"), meas, "snapshot"
    traj = estimate_trajectory(inp, positioning)
    if duration_s < DURATION_CORRELATIONS * traj.correlation_s:
        return _refused(epochs, f"the log lasts {duration_s:.0f} s, less than {DURATION_CORRELATIONS:g} times its errors' correlation time "
                                f"({traj.correlation_s:.0f} s): its noise cannot be measured"), meas, "snapshot"  # fmt: skip
    lat, lon, height = inp.enu2geodetic(traj.enu_m)
    n = len(epochs)
    placed = epochs.assign(snapshot_lat_deg=epochs["lat_deg"].to_numpy(float), snapshot_lon_deg=epochs["lon_deg"].to_numpy(float),
                           lat_deg=lat, lon_deg=lon, height_m=height, sigma_major_m=traj.sigma_major_m,
                           positioning=np.full(n, positioning, dtype=object))  # fmt: skip
    placed.attrs.update(epochs.attrs)
    placed.attrs["trajectory_correlation_s"] = round(traj.correlation_s, 1)
    given = np.isfinite(epochs["odometer_forward_m"].to_numpy(float)) if "odometer_forward_m" in epochs else np.zeros(n, bool)
    contradicted = int((given & ~np.isfinite(inp.forward_m)).sum())
    if contradicted:
        placed.attrs["positioning_note"] = (f"the odometry of {contradicted} of {int(given.sum())} intervals contradicts the fixes "
                                            "(they moved further than it says the vehicle drove): not used there")  # fmt: skip
    meas = replace(meas, trajectory_source=np.full(n, positioning, dtype=object), trajectory_hpl_m=traj.hpl_m,
                   trajectory_test_stat=traj.test_stat, trajectory_dof=traj.dof, trajectory_set_aside=traj.n_set_aside,
                   trajectory_lost=traj.lost)  # fmt: skip
    return placed, meas, positioning


def _refused(epochs, why: str):
    """The epochs as they were, saying why no trajectory placed them (``attrs['positioning_note']``)."""
    out = epochs.copy(deep=False)
    out.attrs.update(epochs.attrs)
    out.attrs["positioning_note"] = why
    return out
