"""A long log's trajectory swept in chunks (``trajectory_sweep``) is the whole log's, bit for bit.

A pass resumed from the state another left (``run_pass(..., resume=...)``) goes on as one pass over the whole would:
every state, covariance, innovation, weight and flag — compiled and twin, forward and backward, across a clock group
that starts late, odometry holes and a jump that makes the pass lose the vehicle. Then the sweep (both passes and their
combination) in chunks against the whole sweep, and the estimator's result on the real Berlin drive; and the noise's
correlation, its residual series transformed a few at a time, against all at once.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import shared
from test_trajectory_kernel import FIELDS, _both, _cases, _same, needs_kernel

from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity import trajectory_noise, trajectory_sweep
from tollcli.integrity.trajectory import _starts, estimate_trajectory
from tollcli.integrity.trajectory_filter import MOTION_STATES, PassBuffers, run_pass, state_after
from tollcli.integrity.trajectory_inputs import trajectory_inputs
from tollcli.integrity.trajectory_sweep import Sweep, sweep


@pytest.fixture(scope="module")
def berlin():
    epochs, meas = pseudorange_epochs(str(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt")), "librsf", None, "nominal",
                                      5.0, NominalModel())  # fmt: skip
    return trajectory_inputs(epochs, meas)


def _in_chunks(inp, sigma2, direction, start, odometry, bounds, robust=None):
    """One pass over ``bounds`` (first, end) in the pass's order, each chunk going on from the state the last left;
    its arrays in the log's order."""
    parts, state = {}, None
    for bound in bounds if direction > 0 else bounds[::-1]:
        part = run_pass(inp, sigma2, direction, *start, odometry, robust_sigma2_m2=robust, rows=bound, resume=state)
        state = state_after(part, -1 if direction > 0 else 0)
        parts[bound] = part
    return {name: np.concatenate([getattr(parts[b], name) for b in bounds]) for name in FIELDS}


@needs_kernel
@pytest.mark.parametrize("case", ["odometry", "no odometry", "odometry holes", "late clock", "jump"])
def test_a_pass_resumed_chunk_by_chunk_is_the_whole_pass_bit_for_bit(berlin, monkeypatch, case):
    inp, odometry = _cases(berlin)[case]
    n = inp.t_s.size
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    robust = np.where(inp.mask, 6.0**2, 900.0)
    start_f, start_b = _starts(inp, odometry, MOTION_STATES)
    bounds = [(a, min(a + 37, n)) for a in range(0, n, 37)]  # edges inside the holes (37), the late clock (74), the jump (111)
    for direction, start in ((1, start_f), (-1, start_b)):
        whole = run_pass(inp, sigma2, direction, *start, odometry, robust_sigma2_m2=robust)
        compiled, twin = _both(monkeypatch, lambda: _in_chunks(inp, sigma2, direction, start, odometry, bounds, robust))
        for name in FIELDS:
            assert _same(compiled[name], getattr(whole, name)), (case, direction, name)
            assert _same(twin[name], getattr(whole, name)), (case, direction, name, "twin")
        if case == "jump" and direction == 1:
            assert compiled["relocked"][90:93].any()  # the case does what it says


@pytest.mark.parametrize("odometry", [True, False])
def test_a_sweep_in_chunks_is_the_whole_sweep_bit_for_bit(berlin, odometry):
    """The real Berlin drive's two passes and their combination, in chunks of 337 epochs and whole: every column."""
    inp = berlin
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    start_f, start_b = _starts(inp, odometry, MOTION_STATES)
    whole = sweep(inp, sigma2, start_f, start_b, odometry)
    chunked = sweep(inp, sigma2, start_f, start_b, odometry, chunk_epochs=337)
    for field in dataclasses.fields(Sweep):
        assert _same(getattr(chunked, field.name), getattr(whole, field.name)), field.name
    assert np.isfinite(whole.x).all() and (whole.dof > 0).all()


@pytest.mark.parametrize("positioning", ["smoothed", "filtered"])
def test_a_long_logs_trajectory_in_chunks_is_the_whole_ones(berlin, monkeypatch, positioning):
    """What the estimator gives a log it sweeps in chunks (every sweep of its noise rounds) is what it gives it whole:
    the real Berlin drive with the chunking threshold lowered below its length."""
    whole = estimate_trajectory(berlin, positioning)
    monkeypatch.setattr(trajectory_sweep, "CHUNKED_FROM_EPOCHS", 500)
    monkeypatch.setattr(trajectory_sweep, "CHUNK_EPOCHS", 300)
    chunked = estimate_trajectory(berlin, positioning)
    for field in dataclasses.fields(whole):
        a, b = getattr(chunked, field.name), getattr(whole, field.name)
        assert (_same(a, b) if isinstance(b, np.ndarray) else a == b), field.name


def test_the_noise_correlation_is_the_same_whatever_the_series_taken_at_once(monkeypatch):
    """Residual series of 40 satellites, each an AR(1) of φ = 0.8 with gaps: the factor 1 + 2 Σ ρ is the same to the
    bit whether the series are transformed one, seven or all at a time — and it is the AR(1)'s, Σ over the lags until
    ρ = 0.8ᵏ < 0.05 (k ≤ 13): 1 + 2 · 0.8 (1 − 0.8¹³) / 0.2 = 8.56."""
    rng = np.random.default_rng(4)
    n_epochs, n_sats = 3000, 40
    z = np.empty((n_epochs, n_sats))
    z[0] = rng.normal(size=n_sats)
    for k in range(1, n_epochs):
        z[k] = 0.8 * z[k - 1] + 0.6 * rng.normal(size=n_sats)
    sv = np.tile(np.array([f"G{i:02d}" for i in range(n_sats)]), (n_epochs, 1))
    mask = rng.random((n_epochs, n_sats)) > 0.02
    results = []
    for at_once in (1, 7, 1000):
        monkeypatch.setattr(trajectory_noise, "SERIES_AT_ONCE", at_once)
        results.append(trajectory_noise.correlation_inflation(z, sv, mask))
    for factor, rho in results[1:]:
        assert factor == results[0][0] and _same(rho, results[0][1])
    assert results[0][0] == pytest.approx(1 + 2 * 0.8 * (1 - 0.8**13) / 0.2, rel=0.1)


@pytest.mark.parametrize("odometry", [True, False])
def test_a_light_sweep_gives_the_full_sweeps_state_and_weights(berlin, odometry):
    """What a round of noise reads of a sweep (``full=False``: the combined state and the weights) is the full sweep's
    to the bit, the rest not made; and passes writing into arrays taken again from a sweep before (``PassBuffers``)
    give what fresh arrays give."""
    inp = berlin
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    start_f, start_b = _starts(inp, odometry, MOTION_STATES)
    full = sweep(inp, sigma2, start_f, start_b, odometry)
    buffers = PassBuffers()
    sweep(inp, sigma2 * 4.0, start_f, start_b, odometry, buffers=buffers)  # the buffers written once by another sweep
    light = sweep(inp, sigma2, start_f, start_b, odometry, full=False, buffers=buffers)
    again = sweep(inp, sigma2, start_f, start_b, odometry, buffers=buffers)
    assert _same(light.x, full.x) and _same(light.weight, full.weight)
    assert light.cov_en_m2 is None and light.test_stat is None and light.relocked is None
    for field in dataclasses.fields(Sweep):
        assert _same(getattr(again, field.name), getattr(full, field.name)), field.name


def _correlation_inflation_by_label(z, sv, mask):
    """The noise correlation as it was first written: every label's series through a zeroed array and np.median (the
    reference the faster one must match to the bit)."""
    n_epochs = z.shape[0]
    ok = mask & np.isfinite(z)
    labels, inverse = np.unique(sv[ok], return_inverse=True)
    rows, values = np.nonzero(ok)[0], z[ok]
    size = 1 << int(np.ceil(np.log2(n_epochs + trajectory_noise.MAX_LAG + 1)))
    power = None
    for label in range(labels.size):
        at = np.flatnonzero(inverse == label)
        value, seen = np.zeros(n_epochs), np.zeros(n_epochs, bool)
        value[rows[at]], seen[rows[at]] = values[at], True
        spec = np.fft.rfft(np.where(seen, value - np.median(value[seen]), 0.0)[None], size, axis=1)
        term = (np.square(spec.real) + np.square(spec.imag))[0]
        power = term.copy() if power is None else power + term
    acf = np.fft.irfft(power, size)[: min(trajectory_noise.MAX_LAG + 1, n_epochs)]
    rho = acf / acf[0]
    below = np.flatnonzero(rho < trajectory_noise.RHO_CUT)
    cut = int(below[0]) if below.size else rho.size
    return float(1.0 + 2.0 * rho[1:cut].sum()), rho


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_noise_correlation_is_the_reference_loops_bit_for_bit(seed):
    """The correlation factor and ρ on residual series with gaps, labels that come and go, and a label twice in some
    epochs (its last value counts): the same bits as the plain per-label loop, by label strings and by their codes."""
    rng = np.random.default_rng(seed)
    n_epochs, n_slots = 1500, 12
    z = rng.standard_t(4, size=(n_epochs, n_slots))
    names = np.array([f"G{i:02d}" for i in range(20)])
    sv = np.stack([rng.permutation(names)[:n_slots] for _ in range(n_epochs)])  # a label once an epoch …
    twice = rng.random(n_epochs) < 0.05
    sv[twice, 1] = sv[twice, 0]  # … but in some epochs, for some labels, twice
    mask = rng.random((n_epochs, n_slots)) > 0.1
    codes = np.unique(sv, return_inverse=True)[1].reshape(sv.shape).astype(np.int32)
    reference = _correlation_inflation_by_label(z, sv, mask)
    for labels in (sv, codes):
        factor, rho = trajectory_noise.correlation_inflation(z, labels, mask)
        assert factor == reference[0] and _same(rho, reference[1])


def test_the_first_pass_is_let_go_before_the_sweeps(berlin, monkeypatch):
    """The noise-scaling pass (run beside the set-up on a thread of its own) holds every measurement's innovation and
    weight; nothing may keep it once its scale is read — not the future it came from — or a long log's peak grows by
    them (0.3 kB an epoch, found by ``trajectory_cost.py --memory``)."""
    import weakref

    from tollcli.integrity import trajectory

    made, alive_at_sweep = [], []
    real_pass, real_sweep = trajectory.run_pass, trajectory.sweep

    def recorded_pass(*args, **kwargs):
        out = real_pass(*args, **kwargs)
        made.append(weakref.ref(out))
        return out

    def checked_sweep(*args, **kwargs):
        alive_at_sweep.append(sum(ref() is not None for ref in made))
        return real_sweep(*args, **kwargs)

    monkeypatch.setattr(trajectory, "run_pass", recorded_pass)
    monkeypatch.setattr(trajectory, "sweep", checked_sweep)
    estimate_trajectory(berlin, "smoothed")
    assert len(made) == 1 and alive_at_sweep == [0] * (1 + trajectory.NOISE_ROUNDS)


def test_the_noise_bins_ask_for_elevations_only_without_c_n0(berlin):
    """The real Berlin drive: with its C/N0 the noise is binned by C/N0 and the elevations are never made; with the
    C/N0 taken away, by the satellites' elevations seen from the frame's origin (above the horizon where measured)."""
    asked = []

    def elevations():
        asked.append(1)
        return berlin.elev_deg

    bins, n_bins, by = trajectory_noise.noise_bins(berlin.cn0_dbhz, elevations, berlin.mask)
    assert by == "cn0" and not asked
    bins, n_bins, by = trajectory_noise.noise_bins(np.full(berlin.mask.shape, np.nan), elevations, berlin.mask)
    assert by == "elevation" and asked == [1] and n_bins == trajectory_noise.ELEVATION_BINS_DEG.size + 1
    elev = berlin.elev_deg[berlin.mask]
    assert (elev > 0).all() and (elev < 90).all()
    assert _same(bins[berlin.mask], np.searchsorted(trajectory_noise.ELEVATION_BINS_DEG, elev, side="right"))
