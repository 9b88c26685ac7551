"""One pass of the robust trajectory filter over a log, forward or backward in time.

An extended Kalman filter in a local east-north-up frame (:class:`TrajectoryInputs`). State:

* with odometry: east, north, up (m), heading ψ (rad, clockwise from north), the gyro's bias (rad/s), clock drift
  (m/s), one receiver clock per constellation (m); the motion is the odometer's distance along ψ and the gyro's turn
  less its bias;
* without: east, north, up, velocity east and north (m/s), drift, clocks; the motion is constant velocity with a
  white acceleration.

Either way the height follows the Earth's surface: the tangent plane at the log's first fix leaves it, (e² + n²) / 2R
below the plane at (e, n) (R :data:`EARTH_RADIUS_M`: 785 m 100 km out), and each step moves the height by the change
of that. A random walk of the height alone could not follow it: on a simulated 8 000 s city drive that ends 100 km
from its start, the smoothed positions' error p95 grew to 20 m in its last hour and 766 of its 40 000 epochs were
beyond their bound; following the surface, p95 is 6 m and none is.

Each epoch's pseudoranges (Sagnac-corrected ranges to the satellites plus the constellation's clock) update the
state with a Cauchy loss: a measurement whose innovation is c normalised standard deviations out counts half, one
far out hardly at all (iteratively reweighted and linearised again while the update moves the position by
:data:`RELINEARISE_M` or more, :data:`ITERATIONS` times at most). A clock group is started at its first
epoch from that epoch's measurements. The backward pass runs the same equations with time reversed; the two are
combined in :mod:`tollcli.integrity.trajectory`.

An epoch whose measurements the pass mostly rejects (at least :data:`LOST_LOCK_MIN`, over half of them weighted
below ½) is one where the pass has lost the vehicle (an odometer slipping, a gyro whose bias jumped): its prior is
widened — position and clocks by 100 m, with odometry the heading by 0.5 rad and the gyro bias by 0.01 rad/s
(without: the velocity by 10 m/s) — so that the measurements take it back. The robust loss alone keeps trusting the
wrong prior and rejects every later measurement too: on a simulated drive with a 10 % odometer and 0.02 rad/s gyro
fault the median error of the whole drive went from 8 to 32 m.

The per-epoch step is sequential by nature (each epoch's prior is the last posterior). It runs in a compiled kernel
(``_trajectory_kernel.c``, about 50 times the numpy loop it replaced) with a plain-Python twin that gives the same
bits (:mod:`tollcli.integrity.trajectory_pass_twin`); this module prepares their arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS
from tollcli.integrity.trajectory_inputs import TrajectoryInputs
from tollcli.integrity.trajectory_pass_twin import EARTH_RADIUS_M  # noqa: F401  (named here: the motion model's)
from tollcli.integrity.trajectory_pass_twin import combine as combine_twin
from tollcli.integrity.trajectory_pass_twin import residuals as residuals_twin
from tollcli.integrity.trajectory_pass_twin import run_pass as run_pass_twin
from tollcli.kernels import compiled_module

C_MPS = 299_792_458.0
#: reweighting iterations per epoch at most
ITERATIONS = 5
#: the Cauchy loss's scale, in normalised innovations
CAUCHY_C = 2.5
#: an epoch's update is linearised again at its result while that moved the position by this or more (m): a move of
#: d leaves a range's linearisation error below d² / (2 × 20 000 km), 2.5 µm at 10 m, and the weights (of the
#: innovations, the same to first order wherever the update is linearised) change by as little
RELINEARISE_M = 10.0
#: how fast the vehicle may have gone (m/s; the start's velocity σ without odometry) where nothing says where it went.
#: At a pass's start, between its first epoch and its first snapshot fix, where the log starts or ends without one
#: (:mod:`tollcli.integrity.trajectory`): the start's position is that fix's, widened by this speed times the time
#: between. Started there as certain as at a fix (30 m), a backward pass over a phone's last 60 s on 3 satellites
#: (20 m/s) began 1.2 km off and stayed 500 m off: the passes disagreed, every epoch of that minute and 3 s before it a
#: fault (``tests/test_trajectory_ends.py``). And across a stretch without odometry (:func:`wander_m2`)
START_SPEED_MPS = 20.0


@dataclass(frozen=True)
class MotionNoise:
    """Process noise of the motion models (variances per second unless said)."""

    along_track_mps: float = 0.1  # odometer speed error, plus ...
    along_track_share: float = 0.03  # ... this share of the speed
    position_m2ps: float = 0.1  # position random walk beside the odometry (lateral slip: ~3 m in 100 s), chosen on the
    # simulator's city drives (benchmarks/trajectory_settings.py: the smallest worst 95th-percentile error, none misleading)
    gap_speed_mps: float = START_SPEED_MPS  # how fast the vehicle may go where an odometry interval is missing (:func:`wander_m2`)
    yaw_rate_radps: float = 0.01  # gyro error
    heading_rad2ps: float = 1e-5  # heading random walk
    up_m2ps: float = 0.01  # height random walk
    clock_m2ps: float = 0.5  # receiver clock random walk
    drift_m2ps3: float = 2.0  # clock drift random walk
    # without odometry: the white acceleration of the constant-velocity model, chosen on the simulator's town drives
    # (turns at up to 2 m/s² sideways, braking and pulling away at 1.5 m/s²: benchmarks/trajectory_settings.py)
    acceleration_m2ps3: float = 2.0
    gyro_bias_rad2ps3: float = 1e-8  # the gyro bias's random walk


@dataclass
class FilterPass:
    """One pass's states per epoch (E, S), their covariances (E, S, S), and each measurement's normalised innovation
    and Cauchy weight (E, N; NaN/0 for empty slots). The priors or the posteriors are None where the pass was asked
    not to keep them (:func:`run_pass`). ``prior_y``/``post_y`` (E, S, S), kept with them: their information matrices
    (the covariances' inverses) as the update made them, all NaN at an epoch it did not update."""

    prior_x: np.ndarray | None
    prior_p: np.ndarray | None
    post_x: np.ndarray | None
    post_p: np.ndarray | None
    z: np.ndarray
    weight: np.ndarray
    odometry: bool
    started: np.ndarray  # (E, C) the clock groups the pass had started by each epoch (a clock it has not tells nothing)
    relocked: np.ndarray  # (E,) epochs where the pass had lost the vehicle and its prior was widened (:func:`_widened`)
    prior_y: np.ndarray | None = None
    post_y: np.ndarray | None = None


class PassBuffers:
    """The arrays the passes of one sweep write, taken again by the next sweep's passes of the same shapes: their
    memory is touched once, not once a sweep (fresh pages, faulted in by the two passes on their two threads at once:
    a pair of passes over 10 000 epochs took 30 ms with fresh arrays against 24–25 ms with reused ones). A pass's results
    must be read before the next pass of the same direction and kind runs (the estimator's rounds read each sweep
    before the next)."""

    def __init__(self) -> None:
        self._arrays: dict[tuple, np.ndarray] = {}

    def take(self, key: tuple, shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
        """An array of ``shape`` for ``key`` (uninitialised): the one taken before where it has that shape."""
        a = self._arrays.get(key)
        if a is None or a.shape != shape or a.dtype != dtype:
            a = self._arrays[key] = np.empty(shape, dtype)
        return a


@dataclass(frozen=True)
class PassState:
    """A pass's state after an epoch — its posterior (S,), (S, S) and the clock groups it had started (C,) — from which
    a pass over the epochs beyond goes on (:func:`run_pass`'s ``resume``) as one pass over the whole would."""

    x: np.ndarray
    p: np.ndarray
    started: np.ndarray


#: states before the clocks: e, n, u, ψ, gyro bias, drift (odometry) or e, n, u, v_e, v_n, drift (without)
MOTION_STATES = 6


def run_pass(inp: TrajectoryInputs, sigma2_m2: np.ndarray, direction: int, start_x: np.ndarray, start_p: np.ndarray,
             odometry: bool, noise: MotionNoise = MotionNoise(), robust_sigma2_m2: np.ndarray | None = None,
             keep: tuple[str, ...] = ("prior", "post"), rows: tuple[int, int] | None = None,
             resume: PassState | None = None, buffers: PassBuffers | None = None) -> FilterPass:  # fmt: skip
    """The filter over every epoch, forward (``direction`` 1) or backward (-1), from ``start_x``/``start_p`` at the
    first epoch it visits (its clocks are started from that epoch's measurements).

    ``sigma2_m2``: each measurement's variance, what it tells the state; ``robust_sigma2_m2`` (default the same): the
    variance its innovation is normalised by for the Cauchy weight — the white part of the error, so that a variance
    inflated for time correlation does not hide a fault from the robust loss.

    ``keep``: which of the states per epoch are kept, ``prior`` and ``post`` (the others are not: a long log's
    covariances are most of the estimator's memory, and the combination reads only the forward posteriors and the
    backward priors).

    ``rows`` (first, end): the pass over those epochs only (its arrays theirs), from ``start_x``/``start_p`` at the first
    it visits — or, with ``resume``, going on from the state a pass left after the epoch just outside them (``first -
    1`` forward, ``end`` backward): then the pass's states, innovations and weights are those of one pass over the whole
    log, bit for bit (tested), and a long log can be swept in chunks (:mod:`tollcli.integrity.trajectory_sweep`).

    ``buffers``: where the pass's arrays come from (:class:`PassBuffers`; default fresh ones).

    The pass itself is the compiled kernel (``_trajectory_kernel.c``) where it was built, else its Python twin
    (:mod:`tollcli.integrity.trajectory_pass_twin`): the same bits either way."""
    robust = sigma2_m2 if robust_sigma2_m2 is None else robust_sigma2_m2
    first, end = (0, inp.mask.shape[0]) if rows is None else rows
    if resume is not None:  # the epoch the state is of, visited first and not again
        first, end = (first - 1, end) if direction > 0 else (first, end + 1)
        start_x, start_p = resume.x, resume.p
    span = slice(first, end)
    n_epochs, n_slots = end - first, inp.mask.shape[1]
    n_states = MOTION_STATES + inp.n_clocks
    keep_prior, keep_post = "prior" in keep, "post" in keep

    def array(kind: str, shape: tuple[int, ...], fill: float | None = None, dtype=np.float64) -> np.ndarray:
        if buffers is None:
            return np.empty(shape, dtype) if fill is None else np.full(shape, fill, dtype)
        a = buffers.take((direction, kind), shape, dtype)
        if fill is not None:
            a.fill(fill)
        return a

    def states(kept: bool, kind: str) -> tuple[np.ndarray, np.ndarray]:  # every epoch written, or nothing
        e = n_epochs if kept else 0
        return array(kind + "_x", (e, n_states)), array(kind + "_p", (e, n_states, n_states))

    out = FilterPass(*states(keep_prior, "prior"), *states(keep_post, "post"), array("z", (n_epochs, n_slots), np.nan),
                     array("weight", (n_epochs, n_slots), 0.0), odometry,
                     array("started", (n_epochs, inp.n_clocks), 0, np.uint8), array("relocked", (n_epochs,), 0, np.uint8),
                     states(keep_prior, "prior_y")[1], states(keep_post, "post_y")[1])  # fmt: skip
    t, sat, pr, mask, clock, speed, yaw, forward, left, origin, rot = inp.kernel_arrays
    wander = wander_m2(inp, direction, noise.gap_speed_mps) if odometry else np.zeros(t.size)  # (read with odometry only)
    started0 = np.zeros(inp.n_clocks, np.uint8) if resume is None else np.ascontiguousarray(resume.started, np.uint8)
    args = (t[span], sat[span], pr[span], mask[span], clock[span], _c64(sigma2_m2[span]), _c64(robust[span]), speed[span],
            yaw[span], forward[span], left[span], wander[span], origin, rot, np.array([getattr(noise, f) for f in NOISE_FIELDS], np.float64),
            _c64(start_x), _c64(start_p), started0, out.prior_x, out.prior_p, out.post_x, out.post_p, out.z, out.weight,
            out.started, out.relocked, out.prior_y, out.post_y, int(direction), int(bool(odometry)), int(inp.n_clocks), ITERATIONS, LOST_LOCK_MIN,
            int(keep_prior), int(keep_post), int(resume is not None), OMEGA_EARTH_RADPS, C_MPS, CAUCHY_C, RELINEARISE_M)  # fmt: skip
    kernel = _kernel()
    (kernel.run_pass if kernel is not None else run_pass_twin)(*args)
    out.started, out.relocked = out.started.astype(bool), out.relocked.astype(bool)
    if not keep_prior:
        out.prior_x = out.prior_p = out.prior_y = None
    if not keep_post:
        out.post_x = out.post_p = out.post_y = None
    if resume is not None:  # the epoch resumed from is not this pass's
        inner = slice(1, None) if direction > 0 else slice(0, -1)
        for name in ("prior_x", "prior_p", "post_x", "post_p", "z", "weight", "started", "relocked", "prior_y", "post_y"):
            value = getattr(out, name)
            if value is not None:
                setattr(out, name, value[inner])
    return out


def wander_m2(inp: TrajectoryInputs, direction: int, speed_mps: float) -> np.ndarray:
    """(E,) the position variance (m², east and north each) a pass in ``direction`` adds over each interval without
    odometry (the one ending at each epoch; 0 where it has odometry). Nothing says where the vehicle went since the
    pass last knew where it was — an epoch with a snapshot fix, or an interval with odometry (or the pass's start):
    ``g`` seconds before this interval of ``dt``. It may have gone ``speed_mps`` × the time since, in any direction, so
    the variance grows as that distance squared: ``speed_mps² × ((g + dt)² − g²)`` — over a gap of T seconds with no
    fix and no odometry, ``(speed_mps × T)²``; between two fixes, ``(speed_mps × dt)²``. A random walk (25 m²/s, the
    rule before) gave 55 m after 120 s where a car goes a kilometre: the pass coming out of a logging gap in a simulated
    city drive rejected the measurements, lost the vehicle, and the minute around the gap was a fault
    (``benchmarks/trajectory_ends.py``). The same bits whole or in chunks: each interval's value comes from the whole
    log's arrays."""
    missing, t = inp.missing_odometry, inp.t_s
    n = t.size
    if not missing.any():  # (the usual log: nothing to add)
        return np.zeros(n)
    dt = np.abs(np.diff(t, prepend=t[:1]))
    fixed = np.isfinite(inp.fix_enu_m).all(axis=1)
    index = np.arange(n)
    if direction > 0:  # interval k runs from epoch k - 1: known there at a fix, after odometry, or at the start
        known = fixed | ~missing
        known[:1] = True
        last = np.maximum.accumulate(np.where(known, index, 0))
        gap = np.zeros(n)
        gap[1:] = t[:-1] - t[last[:-1]]
    else:  # interval k runs from epoch k: known there at a fix, before odometry, or at the start (the last epoch)
        known = fixed.copy()
        known[:-1] |= ~missing[1:]
        known[-1:] = True
        following = np.minimum.accumulate(np.where(known, index, n - 1)[::-1])[::-1]
        gap = t[following] - t
    return np.where(missing, speed_mps * speed_mps * (dt * (2.0 * np.abs(gap) + dt)), 0.0)


def state_after(fp: FilterPass, row: int) -> PassState:
    """The state ``fp`` (kept its posteriors) left after its epoch ``row`` (an index into its arrays)."""
    return PassState(fp.post_x[row].copy(), fp.post_p[row].copy(), fp.started[row].copy())


def _c64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64)


def run_both(inp: TrajectoryInputs, sigma2_m2: np.ndarray, start_f, start_b, odometry: bool, noise: MotionNoise = MotionNoise(),
             robust_sigma2_m2: np.ndarray | None = None, buffers: PassBuffers | None = None) -> tuple[FilterPass, FilterPass]:  # fmt: skip
    """The forward and the backward pass (:func:`run_pass`; ``start_f``/``start_b``: each one's (x, P) at its first
    epoch), the forward keeping its posteriors and the backward its priors (what the combination reads). The two are independent: with the compiled kernel (which lets go of the interpreter) they run at once on
    two threads, each writing only its own arrays, so the result is the same as one after the other."""
    def one(direction, start):  # what the combination reads: the forward posteriors, the backward priors
        return run_pass(inp, sigma2_m2, direction, *start, odometry, noise, robust_sigma2_m2, keep=("post",) if direction > 0 else ("prior",),
                        buffers=buffers)  # fmt: skip

    if _kernel() is None or inp.mask.shape[0] < PARALLEL_MIN_EPOCHS:
        return one(1, start_f), one(-1, start_b)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        backward = pool.submit(one, -1, start_b)
        forward = one(1, start_f)
        return forward, backward.result()


#: the fewest epochs for which the two passes are worth two threads
PARALLEL_MIN_EPOCHS = 500


def combine(xf: np.ndarray, pf: np.ndarray, xb: np.ndarray, pb: np.ndarray, omegas: np.ndarray,
            block: int | None = None, yf: np.ndarray | None = None, yb: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:  # fmt: skip
    """Covariance intersection of two estimates (E, S) with covariances (E, S, S) at every epoch: of the weights
    ``omegas``, the first whose (ω P_f⁻¹ + (1 − ω) P_b⁻¹)⁻¹ has the least horizontal variance; returns that matrix and
    x = P (ω P_f⁻¹ x_f + (1 − ω) P_b⁻¹ x_b) (NaN at an epoch where a matrix is not positive definite). ``block`` 2:
    only each matrix's horizontal (east-north) block is returned, (E, 2, 2); 0: none (None); x is the same. ``yf``,
    ``yb`` (E, S, S): P_f⁻¹ and P_b⁻¹ where the passes made them (:class:`FilterPass` ``post_y``/``prior_y``; all NaN at
    an epoch where not): taken instead of inverting ``pf`` and ``pb`` there. Compiled where built, else the Python
    twin: the same bits."""
    n_epochs, n_states = xf.shape
    side = n_states if block is None else block
    if side not in (0, 2, n_states):
        raise ValueError(f"combine: a block of {side} of {n_states} states")
    x, w = np.empty((n_epochs, n_states)), np.empty(n_epochs)
    p = np.empty((n_epochs if side else 0, side, side))
    args = [np.ascontiguousarray(a, np.float64) for a in (xf, pf, xb, pb, omegas)]
    none = np.empty((0, n_states, n_states))  # (the kernel's "not given")
    given = (none, none) if yf is None or yb is None else (np.ascontiguousarray(yf, np.float64), np.ascontiguousarray(yb, np.float64))
    kernel = _kernel()
    if kernel is None:
        combine_twin(*args, x, p, w, *given)
    elif n_epochs < PARALLEL_MIN_EPOCHS:
        kernel.combine(*args, x, p, w, *given)
    else:  # epochs are independent: the first half on another thread (the kernel lets go of the interpreter)
        from concurrent.futures import ThreadPoolExecutor

        half = n_epochs // 2

        def part(rows: slice) -> None:
            kernel.combine(*(a[rows] for a in args[:4]), args[4], x[rows], p[rows] if side else p, w[rows],
                           *(a[rows] if a.size else a for a in given))  # fmt: skip

        with ThreadPoolExecutor(max_workers=1) as pool:
            first = pool.submit(part, slice(0, half))
            part(slice(half, n_epochs))
            first.result()
    return x, p if side else None


def residuals(inp: TrajectoryInputs, x: np.ndarray) -> np.ndarray:
    """Each measurement's pseudorange less the range from the trajectory ``x`` (E, S) less its constellation's clock
    (E, N; NaN in empty slots), the ranges computed as the pass computes them. Compiled where built, else the Python
    twin: the same bits."""
    n_epochs, n_slots = inp.mask.shape
    out = np.empty((n_epochs, n_slots))
    _t, sat, pr, mask, clock, _v, _w, _f, _l, origin, rot = inp.kernel_arrays
    args = (_c64(x), sat, pr, mask, clock, origin, rot, int(x.shape[1]), int(n_slots), OMEGA_EARTH_RADPS, C_MPS, out)
    kernel = _kernel()
    (kernel.residuals if kernel is not None else residuals_twin)(*args)
    return out


def _kernel():
    """The compiled pass, or None (not built, or ``TOLLCLI_KERNELS=numpy``): looked up on each call so that the
    setting can change within a process (the tests run both)."""
    import os

    if os.environ.get("TOLLCLI_KERNELS", "").lower() == "numpy":
        return None
    global _COMPILED
    if _COMPILED is False:
        _COMPILED = compiled_module("tollcli.integrity._trajectory_kernel")
    return _COMPILED


_COMPILED = False
#: :class:`MotionNoise`'s fields in the order the kernel reads them
NOISE_FIELDS = ("along_track_mps", "along_track_share", "position_m2ps", "gap_speed_mps", "yaw_rate_radps",
                "heading_rad2ps", "up_m2ps", "clock_m2ps", "drift_m2ps3", "acceleration_m2ps3", "gyro_bias_rad2ps3")  # fmt: skip


#: the fewest measurements an epoch needs to say the pass has lost the vehicle
LOST_LOCK_MIN = 5
