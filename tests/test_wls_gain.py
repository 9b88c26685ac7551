"""The batched WLS gain (``wls_geometry``) and the horizontal covariance through the clock block's Schur complement
(``horizontal_covariance``, the model level's) against the normal equations solved epoch by epoch: random geometries of
4–40 satellites on 1–4 clocks (a clock without measurements among them), collinear ones the solve refuses, and every
epoch of a real three-constellation log."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared

from tollcli.gnss import wls


def _geometry(rng, n_epochs, n_slots, n_clocks, empty_clock=False):
    elev = rng.uniform(5.0, 90.0, (n_epochs, n_slots))
    azim = rng.uniform(0.0, 360.0, (n_epochs, n_slots))
    clock = rng.integers(0, n_clocks, (n_epochs, n_slots))
    if empty_clock and n_clocks > 1:
        clock = np.where(clock == n_clocks - 1, 0, clock)  # the last clock has no measurement
    H = wls.observation_matrix(elev, azim, clock, n_clocks)
    sigma = rng.uniform(0.5, 20.0, (n_epochs, n_slots))
    mask = rng.random((n_epochs, n_slots)) < 0.85
    return H, sigma, mask


def _reference(H, sigma, mask):
    """Per epoch (A, d): A = (HᵀWH)⁻¹HᵀW over its active unknowns (zero rows for the others) and d the determinant of
    HᵀWH scaled to a unit diagonal (how the module calls a geometry singular: d ≤ SINGULAR_RCOND); A None there."""
    out = []
    for e in range(H.shape[0]):
        used = mask[e]
        Hu, w = H[e][used], 1.0 / sigma[e][used] ** 2
        active = np.flatnonzero(np.abs(Hu).sum(axis=0) > 0)
        Ha = Hu[:, active]
        G = Ha.T @ (Ha * w[:, None])
        scale = 1.0 / np.sqrt(np.diag(G))
        d = float(np.linalg.det(G * scale[:, None] * scale[None, :])) if active.size else 0.0
        if not d > wls.SINGULAR_RCOND:
            out.append((None, d))
            continue
        A = np.zeros((H.shape[2], H.shape[1]))
        A[np.ix_(active, np.flatnonzero(used))] = np.linalg.solve(G, Ha.T * w)
        out.append((A, d))
    return out


def _check(geometry, reference, H, sigma, mask) -> int:
    """Every epoch's gain as the reference's, its east-north covariance ``horizontal_covariance``'s (A·Σ·Aᵀ), and
    singular where it is (but within rounding of the threshold)."""
    cov, singular, n_meas = wls.horizontal_covariance(H, sigma, mask)
    assert np.array_equal(singular, geometry.singular) and np.array_equal(n_meas, geometry.n_meas)
    checked = 0
    for e, (ref, d) in enumerate(reference):
        if abs(np.log(max(d, 1e-300) / wls.SINGULAR_RCOND)) < 1e-6:
            continue  # on the threshold: either answer is the arithmetic's
        assert geometry.singular[e] == (ref is None), (e, d)
        if ref is None:
            assert (geometry.A[e] == 0.0).all()
            continue
        assert np.allclose(geometry.A[e], ref, rtol=0, atol=1e-9 * np.abs(ref).max()), e
        used = mask[e] & np.isfinite(sigma[e]) & (sigma[e] > 0)
        expected = (ref[:2, used] * sigma[e][used] ** 2) @ ref[:2, used].T
        assert np.allclose(cov[e], expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max()), e
        checked += 1
    return checked


@pytest.mark.parametrize("n_slots,n_clocks,empty", [(4, 1, False), (12, 2, False), (20, 4, True), (40, 3, False), (8, 4, True)])
def test_the_schur_gain_is_the_normal_equations_solution(n_slots, n_clocks, empty):
    rng = np.random.default_rng(n_slots * 10 + n_clocks)
    H, sigma, mask = _geometry(rng, 300, n_slots, n_clocks, empty)
    geometry = wls.wls_geometry(H, sigma, mask)
    assert _check(geometry, _reference(H, sigma, mask), H, sigma, mask) > 100


def test_a_collinear_geometry_is_singular_and_has_no_gain():
    rng = np.random.default_rng(3)
    H, sigma, mask = _geometry(rng, 50, 10, 2)
    H[:10, :, :3] = H[:10, :1, :3]  # every satellite along one line of sight: the position is not solvable
    geometry = wls.wls_geometry(H, sigma, mask)
    assert geometry.singular[:10].all() and not geometry.singular[10:].any()
    assert (geometry.A[:10] == 0.0).all()


def test_clocks_not_one_hot_give_the_same_position():
    """Rows whose clock entries are not one 1 (a clock in other units) solve to the same position gain, the clock's
    scaled: ``horizontal_covariance`` takes them through the gain, not the Schur complement — the same covariance."""
    rng = np.random.default_rng(5)
    H, sigma, mask = _geometry(rng, 200, 14, 2)
    scaled = H.copy()
    scaled[..., 3:] *= 2.0  # the clock in half-units
    one_hot, other = wls.wls_geometry(H, sigma, mask), wls.wls_geometry(scaled, sigma, mask)
    assert wls.clock_groups(np.where(mask[..., None], scaled, 0.0), np.where(mask, 1.0, 0.0)) is None
    ok = ~one_hot.singular
    assert np.allclose(other.A[ok, :3], one_hot.A[ok, :3], rtol=0, atol=1e-9 * np.abs(one_hot.A).max())
    assert np.allclose(other.A[ok, 3:] * 2.0, one_hot.A[ok, 3:], rtol=0, atol=1e-9 * np.abs(one_hot.A).max())
    cov, cov_scaled = wls.horizontal_covariance(H, sigma, mask)[0], wls.horizontal_covariance(scaled, sigma, mask)[0]
    assert np.allclose(cov_scaled[ok], cov[ok], rtol=1e-9, atol=0)


def test_a_real_logs_gain_is_the_normal_equations_solution():
    """Every epoch of a real multi-constellation log (a Quectel L76K: three clocks, 130 epochs)."""
    from tollcli.gnss.nmea_measurements import nmea_measurements
    from tollcli.readers.nmea import read_nmea

    tables = read_nmea(shared("gpsd", "quectel-l76k-dual.log"))
    meas = nmea_measurements(tables.epochs, tables.satellites)
    assert meas.H.shape[-1] - 3 >= 3  # three clocks
    geometry = wls.wls_geometry(meas.H, meas.sigma_m, meas.mask)
    usable = meas.mask & np.isfinite(meas.sigma_m) & (meas.sigma_m > 0)
    assert _check(geometry, _reference(meas.H, meas.sigma_m, usable), meas.H, meas.sigma_m, meas.mask) > 100
