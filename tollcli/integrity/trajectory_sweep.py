"""The forward and the backward pass over a log, combined at every epoch — whole, or chunk by chunk for a long log.

What the trajectory (:mod:`tollcli.integrity.trajectory`) reads of a sweep, per epoch: the combined (smoothed) state
and its horizontal covariance, the forward pass's state and horizontal covariance, the weights the robust loss gave
each measurement, the fault test's statistic and which epochs a pass lost the vehicle at (:class:`Sweep`). The
passes' covariances and their inverses, 4 × (S × S) per epoch, are the estimator's memory; a sweep does not keep them.
A round of noise reads only the combined state and the weights: its sweep is not ``full`` and makes nothing else.

A log of up to :data:`CHUNKED_FROM_EPOCHS` epochs is swept whole: the two passes at once on two threads, then their
combination over the whole log (its two halves on two threads; of each combined covariance only the horizontal block
is made: the passes' own matrices are the memory, not the combination's). A longer one in chunks of
:data:`CHUNK_EPOCHS` (the Build item "overlapping chunks for the backward pass", done exactly rather than with an
overlap):

1. the backward pass over the whole log, chunk by chunk from the end, keeping only its state at each chunk's edge
   (:class:`~tollcli.integrity.trajectory_filter.PassState`), and beside it the forward pass the same way;
2. each chunk's two passes again from those states (``run_pass(..., resume=...)``: the same bits as one pass over the
   whole log), combined and reduced to the per-epoch columns, chunk by chunk on two threads.

The result is the whole sweep's bit for bit (tested on the real Berlin drive in chunks of a few hundred epochs, and
each resumed pass on stretches of it with a late clock, odometry holes and a lost vehicle), for about twice the
passes' time; the memory beyond the log's inputs is a few chunks'
covariances and the per-epoch columns, whatever the log's length (``benchmarks/trajectory_cost.py --memory``).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from tollcli.integrity.trajectory_filter import MOTION_STATES, FilterPass, MotionNoise, PassBuffers, PassState, combine, run_both, run_pass, state_after
from tollcli.integrity.trajectory_inputs import TrajectoryInputs

#: a log longer than this (epochs) is swept in chunks: ~8 matrices (S × S) per epoch kept at once whole, 4.5 kB with
#: two clocks — 74 MB at 16 384 epochs (4.5 h at 1 Hz), the price of chunks being twice the passes' time
CHUNKED_FROM_EPOCHS = 16_384
#: the epochs of a chunk
CHUNK_EPOCHS = 4096
#: the weights ω of covariance intersection tried (:func:`combined`)
OMEGAS = np.linspace(0.05, 0.95, 19)
#: the variance (m²) of a clock a pass has not started: no information
UNKNOWN_M2 = 1e12


@dataclass
class Sweep:
    """A sweep's per-epoch columns: the combined state (E, S) and horizontal covariance (E, 2, 2); the forward pass's
    posterior state and horizontal covariance; the weights (E, N) of both passes (the smaller) and of the forward
    pass; the fault test (:func:`fault_test`); the epochs where either pass lost the vehicle; the backward pass's prior
    state and horizontal covariance. A sweep that was not ``full`` (:func:`sweep`) has only ``x`` and ``weight``."""

    x: np.ndarray
    cov_en_m2: np.ndarray | None
    forward_x: np.ndarray | None
    forward_cov_en_m2: np.ndarray | None
    weight: np.ndarray
    forward_weight: np.ndarray | None
    test_stat: np.ndarray | None
    dof: np.ndarray | None
    relocked: np.ndarray | None
    backward_x: np.ndarray | None = None
    backward_cov_en_m2: np.ndarray | None = None


def sweep(inp: TrajectoryInputs, sigma2_m2: np.ndarray, start_f, start_b, odometry: bool, noise: MotionNoise = MotionNoise(),
          robust_sigma2_m2: np.ndarray | None = None, chunk_epochs: int | None = None, full: bool = True,
          buffers: PassBuffers | None = None) -> Sweep:  # fmt: skip
    """The forward and backward passes (:func:`~tollcli.integrity.trajectory_filter.run_pass`, from ``start_f`` /
    ``start_b``) combined at every epoch. ``chunk_epochs``: sweep in chunks of that many epochs (default: whole up to
    :data:`CHUNKED_FROM_EPOCHS`, else :data:`CHUNK_EPOCHS`) — the same result, bit for bit. ``full`` False: only the
    combined state ``x`` and the ``weight`` (what a round of noise from the residuals reads; the same bits), the other
    columns None. ``buffers``: where a whole sweep's passes take their arrays
    (:class:`~tollcli.integrity.trajectory_filter.PassBuffers`)."""
    n_epochs, n_slots = inp.mask.shape
    n_states = MOTION_STATES + inp.n_clocks

    def empty(shape, dtype=float):
        return np.empty(shape, dtype) if full else None

    out = Sweep(np.empty((n_epochs, n_states)), empty((n_epochs, 2, 2)), empty((n_epochs, n_states)), empty((n_epochs, 2, 2)),
                np.empty((n_epochs, n_slots)), empty((n_epochs, n_slots)), empty(n_epochs), empty(n_epochs, np.int64),
                empty(n_epochs, bool), empty((n_epochs, n_states)), empty((n_epochs, 2, 2)))  # fmt: skip
    chunk = chunk_epochs or (n_epochs if swept_whole(n_epochs) else CHUNK_EPOCHS)
    bounds = [(a, min(a + chunk, n_epochs)) for a in range(0, n_epochs, max(chunk, 1))]
    if len(bounds) <= 1:
        forward, backward = run_both(inp, sigma2_m2, start_f, start_b, odometry, noise, robust_sigma2_m2, buffers)
        _fill(out, 0, forward, backward, full)
        return out

    def edges(direction: int, start) -> dict[tuple[int, int], PassState | None]:
        """Where each chunk's pass goes on from: the state the pass over the chunks before it left (None: the first)."""
        resume, state = {}, None
        for a, b in bounds if direction > 0 else bounds[::-1]:
            resume[(a, b)] = state
            part = run_pass(inp, sigma2_m2, direction, *start, odometry, noise, robust_sigma2_m2, keep=("post",), rows=(a, b), resume=state)
            state = state_after(part, -1 if direction > 0 else 0)  # after the chunk's last epoch visited
        return resume

    def one(bound: tuple[int, int]) -> None:
        forward = run_pass(inp, sigma2_m2, 1, *start_f, odometry, noise, robust_sigma2_m2, keep=("post",), rows=bound,
                           resume=resume_f[bound])  # fmt: skip
        backward = run_pass(inp, sigma2_m2, -1, *start_b, odometry, noise, robust_sigma2_m2, keep=("prior",), rows=bound,
                            resume=resume_b[bound])  # fmt: skip
        _fill(out, bound[0], forward, backward, full)

    with ThreadPoolExecutor(max_workers=2) as pool:  # the kernel lets go of the interpreter; each writes its own rows
        later = pool.submit(edges, -1, start_b)
        resume_f = edges(1, start_f)
        resume_b = later.result()
        for job in [pool.submit(one, bound) for bound in bounds]:
            job.result()
    return out


def swept_whole(n_epochs: int) -> bool:
    """Whether a log of ``n_epochs`` is swept whole by default (else in chunks of :data:`CHUNK_EPOCHS`)."""
    return n_epochs <= CHUNKED_FROM_EPOCHS


def _rows(fp: FilterPass, rows: slice) -> FilterPass:
    """The pass ``fp`` over some of its epochs (views)."""
    def cut(a):
        return None if a is None else a[rows]

    return FilterPass(cut(fp.prior_x), cut(fp.prior_p), cut(fp.post_x), cut(fp.post_p), fp.z[rows], fp.weight[rows], fp.odometry,
                      fp.started[rows], fp.relocked[rows], cut(fp.prior_y), cut(fp.post_y))  # fmt: skip


def _fill(out: Sweep, first: int, forward: FilterPass, backward: FilterPass, full: bool = True) -> None:
    """Rows ``first`` … of ``out`` from a forward pass's posteriors and a backward pass's priors over them (not
    ``full``: the combined state and the weights only)."""
    rows = slice(first, first + forward.weight.shape[0])
    x, p_en = combined(forward, backward, block=2 if full else 0)
    out.x[rows] = x
    out.weight[rows] = np.minimum(forward.weight, backward.weight)
    if not full:
        return
    out.cov_en_m2[rows] = p_en
    out.forward_x[rows], out.forward_cov_en_m2[rows] = forward.post_x, forward.post_p[:, :2, :2]
    out.forward_weight[rows] = forward.weight
    out.test_stat[rows], out.dof[rows] = fault_test(forward, backward)
    out.relocked[rows] = forward.relocked | backward.relocked
    out.backward_x[rows], out.backward_cov_en_m2[rows] = backward.prior_x, backward.prior_p[:, :2, :2]


def fault_test(forward: FilterPass, backward: FilterPass | None) -> tuple[np.ndarray, np.ndarray]:
    """The fault test's statistic and degrees of freedom per epoch.

    After the trip (a backward pass): the horizontal disagreement d = x_f − x_b of the forward posterior and the
    backward prior, against the largest spread it can have whatever the correlation of the two passes' errors
    (σ_d ≤ σ_f + σ_b along any direction, their semi-major axes): t = |d|² / (σ_f + σ_b)², below χ²₂ with at least its
    confidence when both are fault-free. A fault that one pass took in and the other did not (a satellite's bias, an
    odometry step) shows as a disagreement.

    Without a backward pass: the normalised innovations of the measurements the robust loss kept, t = Σ z², χ²_n.
    """
    if backward is None:
        kept = forward.weight >= 0.5
        z2 = np.where(kept, np.nan_to_num(forward.z) ** 2, 0.0)
        return z2.sum(axis=1), kept.sum(axis=1)
    d = forward.post_x[:, :2] - backward.prior_x[:, :2]
    spread = sigma_major_m(forward.post_p[:, :2, :2]) + sigma_major_m(backward.prior_p[:, :2, :2])
    t = (d**2).sum(axis=1) / spread**2
    if not forward.odometry:
        return t, np.full(t.size, 2)
    # the headings too: a gyro bias the passes did not model turns them opposite ways (one integrates it forward, the
    # other backward)
    d_psi = (forward.post_x[:, 3] - backward.prior_x[:, 3] + np.pi) % (2 * np.pi) - np.pi
    spread_psi = np.sqrt(forward.post_p[:, 3, 3]) + np.sqrt(backward.prior_p[:, 3, 3])
    return t + (d_psi / spread_psi) ** 2, np.full(t.size, 3)


def sigma_major_m(cov_en_m2: np.ndarray) -> np.ndarray:
    """The semi-major axis (1σ, m) of horizontal covariances (E, 2, 2)."""
    a, b, c = cov_en_m2[:, 0, 0], cov_en_m2[:, 1, 1], cov_en_m2[:, 0, 1]
    return np.sqrt((a + b) / 2 + np.sqrt(((a - b) / 2) ** 2 + c**2))


def combined(forward: FilterPass, backward: FilterPass | None, block: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """The forward posterior, or with a backward pass the covariance intersection of the forward posterior and the
    backward prior at every epoch (ω on a grid of 19, the first with the least horizontal variance: compiled,
    :func:`tollcli.integrity.trajectory_filter.combine`; ``block`` 2: only the covariance's horizontal block, 0: none).
    A clock group a
    pass has not started by an epoch gives no information there (its variance set to :data:`UNKNOWN_M2`, its
    correlations to zero): only the other pass's value of it counts."""
    if backward is None:
        return forward.post_x, forward.post_p if block is None else forward.post_p[:, :block, :block] if block else None
    m = MOTION_STATES
    xf, pf = forward.post_x, _unknown_clocks(forward.post_p, forward.started, m)
    xb, pb = backward.prior_x, _unknown_clocks(backward.prior_p, backward.started, m)
    if forward.odometry:  # headings compared on the same turn
        xb = xb.copy()
        xb[:, 3] = xf[:, 3] + (xb[:, 3] - xf[:, 3] + np.pi) % (2 * np.pi) - np.pi
    # the passes' information matrices, but where a clock was made unknown (its covariance changed: inverted again)
    yf, yb = (_known_clocks_only(y, fp.started) for y, fp in ((forward.post_y, forward), (backward.prior_y, backward)))
    return combine(np.nan_to_num(xf), pf, np.nan_to_num(xb), pb, OMEGAS, block, yf, yb)


def _known_clocks_only(y: np.ndarray | None, started: np.ndarray) -> np.ndarray | None:
    """Information matrices (E, S, S) with the epochs where a clock was not ``started`` (E, C) set to NaN."""
    if y is None or started.all():
        return y
    y = y.copy()
    y[~started.all(axis=1)] = np.nan
    return y


def _unknown_clocks(p: np.ndarray, started: np.ndarray, m: int) -> np.ndarray:
    """Covariances (E, S, S) with the clocks not ``started`` (E, C) made unknown: variance UNKNOWN_M2, uncorrelated."""
    if started.all():
        return p
    p = p.copy()
    for g in np.flatnonzero(~started.all(axis=0)).tolist():  # a few groups
        rows = ~started[:, g]
        p[rows, m + g, :] = 0.0
        p[rows, :, m + g] = 0.0
        p[rows, m + g, m + g] = UNKNOWN_M2
    return p
