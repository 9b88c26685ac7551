"""One pass of the robust trajectory filter over a log, forward or backward in time.

An extended Kalman filter in a local east-north-up frame (:class:`TrajectoryInputs`). State:

* with odometry: east, north, up (m), heading ψ (rad, clockwise from north), the gyro's bias (rad/s), clock drift
  (m/s), one receiver clock per constellation (m); the motion is the odometer's distance along ψ and the gyro's turn
  less its bias;
* without: east, north, up, velocity east and north (m/s), drift, clocks; the motion is constant velocity with a
  white acceleration.

Each epoch's pseudoranges (Sagnac-corrected ranges to the satellites plus the constellation's clock) update the
state with a Cauchy loss: a measurement whose innovation is c normalised standard deviations out counts half, one
far out hardly at all (iteratively reweighted, :data:`ITERATIONS` at most). A clock group is started at its first
epoch from that epoch's measurements. The backward pass runs the same equations with time reversed; the two are
combined in :mod:`tollcli.integrity.trajectory`.

The per-epoch step is sequential by nature (each epoch's prior is the last posterior): the loop is over epochs, its
body a few small numpy calls on 5 + C states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS
from tollcli.integrity.trajectory_inputs import TrajectoryInputs

C_MPS = 299_792_458.0
#: reweighting iterations per epoch at most
ITERATIONS = 5
#: the Cauchy loss's scale, in normalised innovations
CAUCHY_C = 2.5


@dataclass(frozen=True)
class MotionNoise:
    """Process noise of the motion models (variances per second unless said)."""

    along_track_mps: float = 0.1  # odometer speed error, plus ...
    along_track_share: float = 0.03  # ... this share of the speed
    position_m2ps: float = 0.1  # position random walk beside the odometry (lateral slip: ~3 m in 100 s), chosen on the
    # simulator's city drives (benchmarks/trajectory_settings.py: the smallest worst 95th-percentile error, none misleading)
    no_odometry_m2ps: float = 25.0  # position random walk where an odometry interval is missing
    yaw_rate_radps: float = 0.01  # gyro error
    heading_rad2ps: float = 1e-5  # heading random walk
    up_m2ps: float = 0.01  # height random walk
    clock_m2ps: float = 0.5  # receiver clock random walk
    drift_m2ps3: float = 2.0  # clock drift random walk
    acceleration_m2ps3: float = 4.0
    gyro_bias_rad2ps3: float = 1e-8  # the gyro bias's random walk  # without odometry: white acceleration (constant-velocity model)


@dataclass
class FilterPass:
    """One pass's states per epoch (E, S), their covariances (E, S, S), and each measurement's normalised innovation
    and Cauchy weight (E, N; NaN/0 for empty slots)."""

    prior_x: np.ndarray
    prior_p: np.ndarray
    post_x: np.ndarray
    post_p: np.ndarray
    z: np.ndarray
    weight: np.ndarray
    odometry: bool
    started: np.ndarray  # (E, C) the clock groups the pass had started by each epoch (a clock it has not tells nothing)
    relocked: np.ndarray  # (E,) epochs where the pass had lost the vehicle and its prior was widened (:func:`_widened`)


#: states before the clocks: e, n, u, ψ, gyro bias, drift (odometry) or e, n, u, v_e, v_n, drift (without)
MOTION_STATES = 6


def run_pass(inp: TrajectoryInputs, sigma2_m2: np.ndarray, direction: int, start_x: np.ndarray, start_p: np.ndarray,
             odometry: bool, noise: MotionNoise = MotionNoise(), robust_sigma2_m2: np.ndarray | None = None) -> FilterPass:  # fmt: skip
    """The filter over every epoch, forward (``direction`` 1) or backward (-1), from ``start_x``/``start_p`` at the
    first epoch it visits (its clocks are started from that epoch's measurements).

    ``sigma2_m2``: each measurement's variance, what it tells the state; ``robust_sigma2_m2`` (default the same): the
    variance its innovation is normalised by for the Cauchy weight — the white part of the error, so that a variance
    inflated for time correlation does not hide a fault from the robust loss."""
    robust = sigma2_m2 if robust_sigma2_m2 is None else robust_sigma2_m2
    n_epochs, n_slots = inp.mask.shape
    m = MOTION_STATES
    n_states = m + inp.n_clocks
    prior_x = np.full((n_epochs, n_states), np.nan)
    prior_p = np.full((n_epochs, n_states, n_states), np.nan)
    post_x, post_p = prior_x.copy(), prior_p.copy()
    z_all = np.full((n_epochs, n_slots), np.nan)
    w_all = np.zeros((n_epochs, n_slots))
    started_all = np.zeros((n_epochs, inp.n_clocks), bool)
    relocked = np.zeros(n_epochs, bool)
    order = range(n_epochs) if direction > 0 else range(n_epochs - 1, -1, -1)
    x, p = start_x.astype(float).copy(), start_p.astype(float).copy()
    started = np.zeros(inp.n_clocks, bool)
    rot_t = inp.ecef2enu.T
    previous = None
    for k in order:
        if previous is not None:
            interval = max(k, previous)  # the interval's end epoch (its odometry)
            x, p = _predict(x, p, abs(inp.t_s[k] - inp.t_s[previous]), direction, inp, interval, odometry, m, noise)
        used = np.flatnonzero(inp.mask[k])
        if used.size:
            groups = inp.clock_index[k, used] + m
            x, p, started = _start_clocks(x, p, started, inp.sat_ecef_m[k, used], inp.pr_m[k, used], groups, m, inp, rot_t)
        prior_x[k], prior_p[k] = x, p
        started_all[k] = started
        if used.size:
            args = (inp.sat_ecef_m[k, used], inp.pr_m[k, used], sigma2_m2[k, used], robust[k, used], groups, inp, rot_t)
            x_post, p_post, z, w = _update(x, p, *args)
            if used.size >= LOST_LOCK_MIN and 2 * int((w < 0.5).sum()) > used.size:  # the pass has lost the vehicle
                p = _widened(p, m, odometry)
                prior_p[k] = p
                relocked[k] = True
                x_post, p_post, z, w = _update(x, p, *args)
            x, p = x_post, p_post
            z_all[k, used], w_all[k, used] = z, w
        post_x[k], post_p[k] = x, p
        previous = k
    return FilterPass(prior_x, prior_p, post_x, post_p, z_all, w_all, odometry, started_all, relocked)


#: the fewest measurements an epoch needs to say the pass has lost the vehicle
LOST_LOCK_MIN = 5


def _widened(p, m, odometry):
    """The prior of an epoch whose measurements the pass mostly rejected (a motion it did not model: an odometer
    slipping, a gyro whose bias jumped), widened so that the measurements take it back: position and clocks by
    100 m, with odometry the heading by 0.5 rad and the gyro bias by 0.01 rad/s (without: the velocity by 10 m/s).
    The robust loss alone keeps trusting the wrong prior and rejects every later measurement too: on a simulated
    drive with a 10 % odometer and 0.02 rad/s gyro fault the median error of the whole drive went from 8 to 32 m."""
    p = p.copy()
    add = np.zeros(p.shape[0])
    add[[0, 1, 2]] = 100.0**2
    add[m:] = 100.0**2
    add[3], add[4] = (0.5**2, 0.01**2) if odometry else (10.0**2, 10.0**2)
    p[np.diag_indices_from(p)] += add
    return p


def _predict(x, p, dt_s, direction, inp, interval, odometry, m, noise: MotionNoise):
    """The state ``dt_s`` later (``direction`` -1: earlier), through the interval ending at epoch ``interval``."""
    s = direction * dt_s  # signed time step
    dt = abs(dt_s)
    x = x.copy()
    f = np.eye(x.size)
    q = np.zeros(x.size)
    drift = m - 1
    x[m:] += x[drift] * s
    f[m:, drift] = s
    if odometry:
        v, w = inp.speed_mps[interval], inp.yaw_rate_radps[interval]
        forward, left = inp.forward_m[interval], inp.left_m[interval]
        if np.isfinite(v) and np.isfinite(w) and np.isfinite(forward) and np.isfinite(left):
            # the heading at the interval's start: the state's (forward), or the state's turned back (backward)
            x[3] -= (w - x[4]) * s
            f[3, 4] = s
            psi, dpsi_db = (x[3], s) if direction < 0 else (x[3] + (w - x[4]) * s, 0.0)
            sin, cos = np.sin(psi), np.cos(psi)
            de, dn = forward * sin - left * cos, forward * cos + left * sin  # the dead-reckoned arc, east and north
            x[0] += direction * de
            x[1] += direction * dn
            f[0, 3], f[1, 3] = direction * dn, -direction * de
            f[0, 4], f[1, 4] = direction * dn * dpsi_db, -direction * de * dpsi_db
            sv = noise.along_track_mps + noise.along_track_share * abs(v)
            lateral = (0.5 * noise.yaw_rate_radps * dt * abs(forward)) ** 2  # the gyro's noise turning the arc
            q[0] = (sv * dt * sin) ** 2 + noise.position_m2ps * dt + lateral
            q[1] = (sv * dt * cos) ** 2 + noise.position_m2ps * dt + lateral
            q[3] = (noise.yaw_rate_radps * dt) ** 2 + noise.heading_rad2ps * dt
        else:  # an interval without odometry: the position wanders, the heading too
            q[0] = q[1] = noise.no_odometry_m2ps * dt
            q[3] = 0.1 * dt
        q[2] = noise.up_m2ps * dt
        q[4] = noise.gyro_bias_rad2ps3 * dt
        q[m:] = noise.clock_m2ps * dt
        q[drift] = noise.drift_m2ps3 * dt
        p = f @ p @ f.T + np.diag(q)
        return x, p
    x[0] += x[3] * s
    x[1] += x[4] * s
    f[0, 3] = f[1, 4] = s
    qa = noise.acceleration_m2ps3
    p = f @ p @ f.T
    for pos, vel in ((0, 3), (1, 4)):
        p[pos, pos] += qa * dt**3 / 3
        p[pos, vel] += qa * s * dt / 2
        p[vel, pos] += qa * s * dt / 2
        p[vel, vel] += qa * dt
    p[2, 2] += noise.up_m2ps * dt
    idx = np.arange(m, x.size)
    p[idx, idx] += noise.clock_m2ps * dt
    p[drift, drift] += noise.drift_m2ps3 * dt
    return x, p


def _ranges(x, sat, inp, rot_t):
    """Sagnac-corrected ranges (m) from the state's position to ``sat`` (K, 3) and the ENU unit vectors (K, 3)."""
    pos = inp.origin_ecef_m + rot_t @ x[:3]
    rough = np.sqrt(((sat - pos) ** 2).sum(axis=1))
    theta = OMEGA_EARTH_RADPS * rough / C_MPS
    c, s = np.cos(theta), np.sin(theta)
    vec = np.stack([c * sat[:, 0] + s * sat[:, 1], -s * sat[:, 0] + c * sat[:, 1], sat[:, 2]], axis=1) - pos
    rng = np.sqrt((vec**2).sum(axis=1))
    return rng, (vec / rng[:, None]) @ rot_t


def _start_clocks(x, p, started, sat, pr, groups, m, inp, rot_t):
    """Clock groups seen for the first time: their clock from this epoch's measurements (median), variance 100² m²."""
    new = np.unique(groups[~started[groups - m]])
    if new.size == 0:
        return x, p, started
    rng, _ = _ranges(x, sat, inp, rot_t)
    x, p, started = x.copy(), p.copy(), started.copy()
    for g in new.tolist():
        x[g] = np.median((pr - rng)[groups == g])
        p[g, :] = p[:, g] = 0.0
        p[g, g] = 100.0**2 + p[0, 0] + p[1, 1] + p[2, 2]
        started[g - m] = True
    return x, p, started


def _update(x_prior, p_prior, sat, pr, sigma2, robust2, groups, inp, rot_t):
    """The robust (Cauchy, iteratively reweighted) measurement update of one epoch, in information form."""
    k = pr.size
    info_prior = np.linalg.inv(p_prior)
    x = x_prior
    h = np.zeros((k, x_prior.size))
    rows = np.arange(k)
    for _ in range(ITERATIONS):
        rng, u_enu = _ranges(x, sat, inp, rot_t)
        h[:, :3] = -u_enu
        h[rows, groups] = 1.0
        r = pr - rng - x[groups] - h @ (x_prior - x)  # the innovation, linearised at x
        s_diag = np.einsum("ij,jk,ik->i", h, p_prior, h) + robust2
        z = r / np.sqrt(s_diag)
        w = 1.0 / (1.0 + (z / CAUCHY_C) ** 2)
        wd = w / sigma2
        p_post = np.linalg.inv(info_prior + (h.T * wd) @ h)
        x_new = x_prior + p_post @ (h.T @ (wd * r))
        done = np.abs(x_new[:3] - x[:3]).max() < 1e-3
        x = x_new
        if done:
            break
    return x, 0.5 * (p_post + p_post.T), z, w
