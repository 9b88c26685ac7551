"""The compiled trajectory kernel (``tollcli/integrity/_trajectory_kernel.c``) against its Python twin.

The twin (``trajectory_pass_twin``) is the reference and the fallback where the kernel was not built; the two must
give the same bits — every state, covariance, innovation, weight and flag of a pass, every combined estimate, every
residual — so that an invoice does not depend on whether the machine had a C compiler. Checked on stretches of the
real Berlin drive: with and without its odometry, with odometry missing over intervals, with a clock group that
starts late, with a jump that makes the pass lose the vehicle, forward and backward. The install builds the kernel
(setup.py); where it could not, the first test says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import shared
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity import trajectory_filter
from tollcli.integrity.trajectory import _starts
from tollcli.integrity.trajectory_filter import MOTION_STATES, combine, residuals, run_pass
from tollcli.integrity.trajectory_inputs import trajectory_inputs
from tollcli.integrity.trajectory_sweep import OMEGAS
from tollcli.integrity.trajectory_sweep import combined as _combined

kernel = trajectory_filter._kernel()
needs_kernel = pytest.mark.skipif(kernel is None, reason="trajectory kernel not built")
FIELDS = ("prior_x", "prior_p", "post_x", "post_p", "z", "weight", "started", "relocked", "prior_y", "post_y")


def test_the_install_built_the_trajectory_kernel():
    """`pip install .` compiles it (a C compiler and Python's headers are on this machine and in CI)."""
    assert kernel is not None, "trajectory kernel not built (see README: pip install needs a C compiler)"
    assert kernel.__name__ == "tollcli.integrity._trajectory_kernel"


@pytest.fixture(scope="module")
def berlin():
    epochs, meas = pseudorange_epochs(str(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt")), "librsf", None, "nominal",
                                      5.0, NominalModel())  # fmt: skip
    return trajectory_inputs(epochs, meas)


def _stretch(inp, start: int, n: int, **changes):
    """Epochs start … start + n of the inputs, with some arrays replaced."""
    cut = {f.name: getattr(inp, f.name)[start : start + n] for f in dataclasses.fields(inp) if f.name not in ("origin_ecef_m", "ecef2enu")}
    cut.update(changes)
    return dataclasses.replace(inp, **cut)


def _both(monkeypatch, fn):
    """``fn()`` with the compiled kernel, then with the Python twin."""
    compiled = fn()
    monkeypatch.setenv("TOLLCLI_KERNELS", "numpy")
    twin = fn()
    monkeypatch.delenv("TOLLCLI_KERNELS")
    return compiled, twin


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _cases(inp):
    n = 160
    base = _stretch(inp, 400, n)
    holes = base.speed_mps.copy()
    holes[40:55] = np.nan  # no odometry over 15 intervals
    late = base.mask.copy()
    late[:60] &= base.clock_index[:60] == 0  # the second clock group seen only from epoch 60
    jump = base.pr_m.copy()
    jump[90:93] += 400.0  # every pseudorange 400 m long for three epochs: the pass loses the vehicle
    return {
        "odometry": (base, True),
        "no odometry": (base, False),
        "odometry holes": (dataclasses.replace(base, speed_mps=holes, forward_m=np.where(np.isnan(holes), np.nan, base.forward_m)), True),
        "late clock": (dataclasses.replace(base, mask=late), True),
        "jump": (dataclasses.replace(base, pr_m=jump), True),
    }


@needs_kernel
@pytest.mark.parametrize("case", ["odometry", "no odometry", "odometry holes", "late clock", "jump"])
def test_pass_is_the_twins_bit_for_bit(berlin, monkeypatch, case):
    inp, odometry = _cases(berlin)[case]
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    robust = np.where(inp.mask, 6.0**2, 900.0)
    start_f, start_b = _starts(inp, odometry, MOTION_STATES)
    for direction, start in ((1, start_f), (-1, start_b)):
        compiled, twin = _both(monkeypatch, lambda: run_pass(inp, sigma2, direction, *start, odometry, robust_sigma2_m2=robust))
        for name in FIELDS:
            assert _same(getattr(compiled, name), getattr(twin, name)), (case, direction, name)
        assert np.isfinite(compiled.post_x).all()
        if case == "jump" and direction == 1:
            assert compiled.relocked[90:93].any()  # the case does what it says
        if case == "late clock":
            assert not compiled.started[:60, 1].any() or direction == -1


@needs_kernel
@pytest.mark.parametrize("keep", [("post",), ("prior",), ()])
def test_a_pass_keeping_half_its_states_keeps_them_as_a_whole_pass_does(berlin, monkeypatch, keep):
    """A pass asked to keep only its posteriors (or its priors, or neither) gives those, and everything else it
    gives, to the bit of a pass that keeps both — compiled and twin — and the others not at all (None: memory a long
    log does not spend)."""
    inp, odometry = _cases(berlin)["jump"]
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    start_f, _ = _starts(inp, odometry, MOTION_STATES)
    whole = run_pass(inp, sigma2, 1, *start_f, odometry)
    compiled, twin = _both(monkeypatch, lambda: run_pass(inp, sigma2, 1, *start_f, odometry, keep=keep))
    for half in (compiled, twin):
        for name in FIELDS:
            kept = name not in ("prior_x", "prior_p", "post_x", "post_p", "prior_y", "post_y") or name.split("_")[0] in keep
            assert (_same(getattr(half, name), getattr(whole, name)) if kept else getattr(half, name) is None), (keep, name)


@needs_kernel
def test_combination_and_residuals_are_the_twins_bit_for_bit(berlin, monkeypatch):
    inp, odometry = _cases(berlin)["late clock"]
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    start_f, start_b = _starts(inp, odometry, MOTION_STATES)
    forward = run_pass(inp, sigma2, 1, *start_f, odometry)
    backward = run_pass(inp, sigma2, -1, *start_b, odometry)
    (x, p), (x_twin, p_twin) = _both(monkeypatch, lambda: _combined(forward, backward))
    assert _same(x, x_twin) and _same(p, p_twin) and np.isfinite(x).all()
    res, res_twin = _both(monkeypatch, lambda: residuals(inp, x))
    assert _same(res, res_twin)
    assert np.isnan(res[~inp.mask]).all() and np.isfinite(res[inp.mask]).all()


def _random_spd(rng, n):
    a = rng.normal(size=(n, n)) * rng.uniform(0.1, 30.0, size=n)
    return a @ a.T + np.eye(n) * rng.uniform(1e-3, 1.0)


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(6, 10))
@example(97240, 10)
def test_the_weight_found_by_halving_is_the_grids_first_least(seed, n):
    """Property: the horizontal variance of (ω P_f⁻¹ + (1 − ω) P_b⁻¹)⁻¹ is convex in ω, so the kernel's halving finds
    the first least of the grid, as trying all 19 does (wherever the two best differ beyond rounding)."""
    rng = np.random.default_rng(seed)
    pf, pb = _random_spd(rng, n), _random_spd(rng, n)
    xf, xb = rng.normal(size=n), rng.normal(size=n)
    x, p = combine(xf[None], pf[None], xb[None], pb[None], OMEGAS)
    info_f, info_b = np.linalg.inv(pf), np.linalg.inv(pb)
    traces = np.array([np.trace(np.linalg.inv(w * info_f + (1 - w) * info_b)[:2, :2]) for w in OMEGAS])
    best = int(np.argmin(traces))
    chosen = int(np.argmin(np.abs(OMEGAS - _omega_of(p[0], info_f, info_b))))
    close = np.abs(traces - traces[best]) <= 1e-9 * traces[best]
    assert close[chosen], (traces, best, chosen)
    w = OMEGAS[chosen]
    expected = np.linalg.inv(w * info_f + (1 - w) * info_b)
    # to rounding of the matrix's own scale: an entry 1e-6 of its largest differed by 7e-12 (seed 97240, n 10) between two
    # inversions of the same matrix, beyond 1e-8 of itself
    assert np.allclose(p[0], expected, rtol=1e-8, atol=1e-12 * np.abs(expected).max())
    assert np.allclose(x[0], p[0] @ (w * info_f @ xf + (1 - w) * info_b @ xb), rtol=1e-7, atol=1e-9)


def _omega_of(p, info_f, info_b) -> float:
    """The ω whose combination is ``p``: p⁻¹ = ω I_f + (1 − ω) I_b, solved by least squares."""
    d = (info_f - info_b).ravel()
    return float(d @ (np.linalg.inv(p) - info_b).ravel() / (d @ d))


@needs_kernel
@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(6, 10), st.integers(1, 6))
def test_the_combinations_blocks_and_given_inverses_agree(seed, n, n_epochs):
    """Property: the combination asked for the horizontal block only (``block=2``), or for nothing (``block=0``), gives
    the same x to the bit, and the block is the whole matrix's to the bit; given the two estimates' information matrices
    (what the passes made) it agrees with inverting their covariances to rounding, and an epoch whose given matrix is
    NaN is inverted as if none were given — compiled and twin alike."""
    rng = np.random.default_rng(seed)
    pf = np.stack([_random_spd(rng, n) for _ in range(n_epochs)])
    pb = np.stack([_random_spd(rng, n) for _ in range(n_epochs)])
    xf, xb = rng.normal(size=(n_epochs, n)), rng.normal(size=(n_epochs, n))
    yf, yb = np.linalg.inv(pf), np.linalg.inv(pb)
    missing = yf.copy()
    missing[0] = np.nan  # the first epoch: not given

    def all_ways():
        return (combine(xf, pf, xb, pb, OMEGAS), combine(xf, pf, xb, pb, OMEGAS, block=2), combine(xf, pf, xb, pb, OMEGAS, block=0),
                combine(xf, pf, xb, pb, OMEGAS, None, yf, yb), combine(xf, pf, xb, pb, OMEGAS, None, missing, yb))  # fmt: skip

    with pytest.MonkeyPatch.context() as monkeypatch:
        compiled, twin = _both(monkeypatch, all_ways)
    for a, b in zip(compiled, twin):
        assert _same(a[0], b[0]) and (a[1] is None and b[1] is None or _same(a[1], b[1]))
    (x, p), (x2, p2), (x0, p0), (xy, py), (xm, pm) = compiled
    assert _same(x2, x) and _same(x0, x) and p0 is None
    assert _same(p2, p[:, :2, :2])
    # inverting a matrix loses digits in proportion to its condition number (random ones here reach 4·10⁵)
    rtol = 1e-11 * max(np.linalg.cond(pf).max(), np.linalg.cond(pb).max(), 1e4)
    assert np.allclose(xy, x, rtol=rtol, atol=rtol * np.abs(x).max()) and np.allclose(py, p, rtol=rtol, atol=rtol * np.abs(p).max())
    assert _same(xm[0], x[0]) and _same(pm[0], p[0])  # not given: inverted
    assert _same(xm[1:], xy[1:]) and _same(pm[1:], py[1:])  # given: taken


@needs_kernel
def test_the_passes_information_matrices_are_their_covariances_inverses(berlin):
    """What a pass gives the combination instead of inverting again: at every epoch it updated, the prior's and the
    posterior's information matrices are the inverses of the covariances it keeps (to rounding); NaN at an epoch
    without measurements."""
    inp, odometry = _cases(berlin)["late clock"]
    inp = dataclasses.replace(inp, mask=np.where(np.arange(inp.mask.shape[0])[:, None] == 30, False, inp.mask))
    sigma2 = np.where(inp.mask, 8.0**2, 900.0)
    start_f, _ = _starts(inp, odometry, MOTION_STATES)
    fp = run_pass(inp, sigma2, 1, *start_f, odometry)
    updated = inp.mask.any(axis=1)
    assert not updated[30] and np.isnan(fp.prior_y[30]).all() and np.isnan(fp.post_y[30]).all()
    for y, p in ((fp.prior_y, fp.prior_p), (fp.post_y, fp.post_p)):
        eye = np.einsum("eij,ejk->eik", y[updated], p[updated])
        assert np.allclose(eye, np.eye(p.shape[1]), atol=1e-6)


@pytest.mark.parametrize("odometry", [True, False])
def test_the_height_follows_the_earths_surface_away_from_the_origin(berlin, monkeypatch, odometry):
    """Without measurements a pass dead-reckons (on its odometry, or at its start velocity): its height falls as the
    tangent plane at the log's origin leaves the Earth's surface — (e² + n²) / 2R below the plane at (e, n) — not stays
    in the plane (a 100 km drive ended 785 m above its road; 766 misleading epochs on a simulated one). Compiled and
    twin alike."""
    from tollcli.integrity.trajectory_filter import EARTH_RADIUS_M

    inp = _stretch(berlin, 0, 400)
    speed = np.full(inp.t_s.size, 30.0)  # straight on at 30 m/s, no turn
    dt = np.diff(inp.t_s, prepend=inp.t_s[0])
    inp = dataclasses.replace(inp, mask=np.zeros_like(inp.mask), speed_mps=speed, yaw_rate_radps=np.zeros_like(speed),
                              forward_m=speed * dt, left_m=np.zeros_like(speed))  # fmt: skip
    x0, p0 = _starts(inp, odometry, MOTION_STATES)[0]
    x0 = x0.copy()
    x0[:3] = (20_000.0, -35_000.0, 12.0)  # 40 km out: the plane is already 126 m above the road there
    if odometry:
        x0[3:5] = (np.arctan2(20_000.0, -35_000.0), 0.0)  # heading away from the origin (clockwise from north), no gyro bias
    else:
        x0[3:5] = (21.0, -21.0)  # the velocity, east and north: away from the origin
    for kernels in ("compiled", "numpy"):
        if kernels == "numpy":
            monkeypatch.setenv("TOLLCLI_KERNELS", "numpy")
        elif kernel is None:
            continue
        x = run_pass(inp, np.full(inp.mask.shape, 900.0), 1, x0, p0, odometry).post_x
        below = (x[:, 0] ** 2 + x[:, 1] ** 2) / (2 * EARTH_RADIUS_M)
        moved = np.hypot(x[-1, 0] - x[0, 0], x[-1, 1] - x[0, 1])
        assert moved > 1_000.0  # the case does what it says: it drove on
        assert np.allclose(x[:, 2] + below, 12.0 + (x0[0] ** 2 + x0[1] ** 2) / (2 * EARTH_RADIUS_M), rtol=0, atol=1e-6), kernels
        assert x[-1, 2] < x[0, 2] - 1.0  # away from the origin, downhill in the plane
