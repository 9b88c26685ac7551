"""The batched WLSR RAIM on synthetic geometry: statistics, a loop reference, FDE, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.wls import observation_matrix, residuals_from_prefit, wls_geometry, wsse
from tollcli.integrity.fde import exclude
from tollcli.integrity.raim import EXCLUDED, FAULT, RaimParams, detect
from tollcli.integrity.run import run_raim


def _scene(seed: int, n_epochs: int, n_sats: int, n_clocks: int = 1):
    rng = np.random.default_rng(seed)
    el = rng.uniform(10, 85, (n_epochs, n_sats))
    az = rng.uniform(0, 360, (n_epochs, n_sats))
    clock = rng.integers(0, n_clocks, (n_epochs, n_sats))
    clock[:, :n_clocks] = np.arange(n_clocks)  # every clock in use
    clock[:, n_clocks : 2 * n_clocks] = np.arange(n_clocks)  # ... by at least two satellites
    H = observation_matrix(el, az, clock, n_clocks)
    sigma = rng.uniform(1.0, 6.0, (n_epochs, n_sats))
    mask = np.ones((n_epochs, n_sats), dtype=bool)
    return rng, H, sigma, mask


def test_fault_free_statistic_follows_chi2_k():
    rng, H, sigma, mask = _scene(1, 4000, 9, n_clocks=2)
    mask[::3, 8] = False  # mixed k across epochs: 4 and 3
    geom = wls_geometry(H, sigma, mask)
    dy = rng.normal(0.0, sigma) + 1e4 * rng.normal(size=(4000, 1))  # any common clock offset is absorbed
    r, _ = residuals_from_prefit(H, geom, dy, mask)
    t = wsse(r, geom)
    assert set(np.unique(geom.dof)) == {3, 4}
    u = stats.chi2.cdf(t, geom.dof)  # uniform if t ~ χ²_k
    assert stats.kstest(u, "uniform").pvalue > 0.01
    # and the test can tell a wrong k
    assert stats.kstest(stats.chi2.cdf(t, geom.dof + 1), "uniform").pvalue < 1e-6


def test_bias_at_lambda_det_is_detected_with_1_minus_pmd():
    rng, H, sigma, mask = _scene(2, 20_000, 8)
    geom = wls_geometry(H, sigma, mask)
    params = RaimParams("classic", hal_m=1e6, p_md=0.1, p_fa=0.01)
    clean = wsse(residuals_from_prefit(H, geom, rng.normal(0, sigma), mask)[0], geom)
    det = detect(geom, clean, params)
    worst = np.nanargmax(geom.slope, axis=1)
    rows = np.arange(H.shape[0])
    bias = np.sqrt(det.lambda_det * sigma[rows, worst] ** 2 / geom.redundancy[rows, worst])
    dy = rng.normal(0, sigma)
    dy[rows, worst] += bias
    r, dx = residuals_from_prefit(H, geom, dy, mask)
    detected = np.mean(wsse(r, geom) > det.threshold)
    n = H.shape[0]
    assert abs(detected - 0.9) < 4 * np.sqrt(0.9 * 0.1 / n)
    # the bias alone moves the horizontal position by exactly HPL = slope_max·√λ_det
    only_bias = np.zeros_like(dy)
    only_bias[rows, worst] = bias
    _, dxb = residuals_from_prefit(H, geom, only_bias, mask)
    assert np.hypot(dxb[:, 0], dxb[:, 1]) == pytest.approx(det.hpl_m, rel=1e-9)


def test_etc_bias_reaching_hal_is_detected_with_1_minus_pmd():
    rng, H, sigma, mask = _scene(3, 20_000, 8)
    geom = wls_geometry(H, sigma, mask)
    params = RaimParams("etc", hal_m=40.0, p_md=0.05, exact_threshold=True)
    det = detect(geom, np.zeros(H.shape[0]), params)
    worst = np.nanargmax(geom.slope, axis=1)
    rows = np.arange(H.shape[0])
    bias = np.sqrt(det.lambda_det * sigma[rows, worst] ** 2 / geom.redundancy[rows, worst])
    dy = rng.normal(0, sigma)
    dy[rows, worst] += bias
    t = wsse(residuals_from_prefit(H, geom, dy, mask)[0], geom)
    n = H.shape[0]
    assert abs(np.mean(t > det.threshold) - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n)
    assert (det.hpl_m == 40.0).all()


def _reference_per_epoch(H, sigma, mask, dy):
    """Parity-space RAIM written differently: a Python loop with QR (thesis App. D.4)."""
    t_out, red_out, slope_out = [], [], []
    for e in range(H.shape[0]):
        m = mask[e]
        h = H[e][m]
        h = h[:, np.abs(h).sum(0) > 0]
        w_half = 1.0 / sigma[e][m]
        hn = h * w_half[:, None]
        q, _ = np.linalg.qr(hn, mode="complete")
        parity = q[:, h.shape[1] :].T  # rows span the left null space of Σ^-1/2 H
        z = parity @ (w_half * dy[e][m])
        t_out.append(z @ z)
        redundancy = np.sum(parity**2, axis=0)
        gain = np.linalg.pinv(hn) * w_half[None, :]  # A = (HᵀWH)⁻¹HᵀW
        slope_out.append(np.max(sigma[e][m] * np.hypot(gain[0], gain[1]) / np.sqrt(redundancy)))
        red_out.append(redundancy)
    return np.array(t_out), red_out, np.array(slope_out)


def test_batched_raim_matches_a_per_epoch_parity_space_reference():
    rng, H, sigma, mask = _scene(4, 60, 10, n_clocks=3)
    mask[rng.random(mask.shape) < 0.15] = False
    mask[:, :6] = True
    dy = rng.normal(0, sigma) * 3
    geom = wls_geometry(H, sigma, mask)
    t = wsse(residuals_from_prefit(H, geom, dy, mask)[0], geom)
    t_ref, red_ref, slope_ref = _reference_per_epoch(H, sigma, mask, dy)
    assert t == pytest.approx(t_ref, rel=1e-9)
    assert geom.slope_max_m == pytest.approx(slope_ref, rel=1e-9)
    for e in range(H.shape[0]):
        assert geom.redundancy[e][mask[e]] == pytest.approx(red_ref[e], abs=1e-12)


def test_fde_excludes_the_faulty_satellite_and_moves_the_position_to_the_subset_solution():
    rng, H, sigma, mask = _scene(5, 2000, 10)
    geom = wls_geometry(H, sigma, mask)
    dy = rng.normal(0, sigma)
    dy[:, 4] += 150.0
    r, dx = residuals_from_prefit(H, geom, dy, mask)
    params = RaimParams("etc", hal_m=50.0, p_md=5e-5, fde=True)
    det = detect(geom, wsse(r, geom), params)
    flagged = det.status == FAULT
    assert flagged.mean() > 0.99
    ex = exclude(H, sigma, mask, r, geom, det, params)
    done = det.status == EXCLUDED
    assert done.mean() > 0.8  # the others have several passing subsets: no exclusion is safe there
    assert ((det.status == EXCLUDED) | (det.status == FAULT))[flagged].all()  # never valid with the fault in
    assert (ex.excluded_slot[done] == 4).mean() > 0.99
    # the shifted position equals a WLS solved without satellite 4 (leave-one-out identity)
    sub_mask = mask.copy()
    sub_mask[:, 4] = False
    sub = wls_geometry(H, sigma, sub_mask)
    _, dx_sub = residuals_from_prefit(H, sub, dy, sub_mask)
    assert (dx[:, :3] + ex.shift_enu_m)[done] == pytest.approx(dx_sub[done, :3], abs=1e-6)
    assert det.dof[done].max() == geom.dof.max() - 1


def test_bad_input_gets_statuses_not_exceptions():
    n_epochs, n_slots = 6, 5
    el = np.tile(np.array([15.0, 30.0, 45.0, 60.0, 75.0]), (n_epochs, 1))
    az = np.tile(np.array([0.0, 72.0, 144.0, 216.0, 288.0]), (n_epochs, 1))
    H = observation_matrix(el, az, np.zeros((n_epochs, n_slots), int), 1)
    sigma = np.full((n_epochs, n_slots), 3.0)
    mask = np.ones((n_epochs, n_slots), dtype=bool)
    mask[0] = False  # no satellites
    mask[1, 3:] = False  # fewer measurements than unknowns + 1
    sigma[2, 1] = np.nan  # a NaN σ: that measurement is not used
    H[3, 1] = H[3, 0]  # a duplicated satellite: same line of sight twice
    mask[4, 4] = False
    H[4, :4, :3] = H[4, 0, :3]  # all from one direction: singular geometry
    residual = np.zeros((n_epochs, n_slots))
    residual[5, 2] = np.nan  # a missing residual: no test statistic
    meas = Measurements(H, sigma, mask, np.full((n_epochs, n_slots), "G01", dtype=object), residual_m=residual)
    for mode in ("etc", "classic"):
        out = run_raim(meas, RaimParams(mode, fde=True))
        status = out["raim_status"].tolist()
        assert status[0] == status[1] == status[2] == status[4] == "insufficient"
        assert status[5] in ("unmonitored", "unavailable")
        assert status[3] in ("valid", "unavailable", "insufficient", "fault_detected")
