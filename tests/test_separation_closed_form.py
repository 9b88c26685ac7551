"""Solution separation in closed form (low-rank updates of the all-in-view solution) against the direct solve of every
subset, over random geometries: 4–40 satellites, 1–3 receiver clocks, a constellation of one satellite, geometries near
singular, with and without pairs of satellites monitored."""

import numpy as np
import pytest

from tollcli.gnss.wls import observation_matrix, post_fit_residuals, wls_geometry
from tollcli.integrity.solution_separation import clock_columns, solution_separation


def random_epochs(rng, n_epochs: int, n_slots: int, n_clocks: int, lone: bool, flat: bool):
    elev = rng.uniform(5, 90, (n_epochs, n_slots))
    azim = rng.uniform(0, 360, (n_epochs, n_slots))
    if flat:  # every satellite in one patch of sky: a geometry near singular
        elev, azim = rng.uniform(30, 35, (n_epochs, n_slots)), rng.uniform(0, 20, (n_epochs, n_slots))
    clock = rng.integers(0, n_clocks, (n_epochs, n_slots))
    if lone and n_clocks > 1:  # the last constellation has one satellite: it only fixes its own clock
        clock[:, 0] = n_clocks - 1
        clock[:, 1:] = rng.integers(0, n_clocks - 1, (n_epochs, n_slots - 1))
    H = observation_matrix(elev, azim, clock, n_clocks)
    sigma = rng.uniform(1, 10, (n_epochs, n_slots))
    mask = rng.random((n_epochs, n_slots)) < rng.uniform(0.5, 1.0)
    mask[:, :4] = True
    dy = rng.normal(0, 1, (n_epochs, n_slots)) * sigma
    dy[rng.random((n_epochs, n_slots)) < 0.05] += 50.0  # some faults
    geometry = wls_geometry(H, sigma, mask)
    residual, _ = post_fit_residuals(H, geometry, mask, dy, None)
    return H, sigma, mask, np.nan_to_num(residual), geometry, dy


@pytest.mark.parametrize("seed", range(6))
def test_the_closed_form_gives_the_direct_solves_verdicts(seed):
    rng = np.random.default_rng(seed)
    compared = 0
    for trial in range(60):
        n_slots, n_clocks = int(rng.integers(4, 41)), int(rng.integers(1, 4))
        p_sat = 1e-3 if trial % 3 == 0 else 1e-5  # 1e-3: pairs of satellites are monitored too
        H, sigma, mask, r, geometry, dy = random_epochs(rng, 6, n_slots, n_clocks, lone=trial % 5 == 0, flat=trial % 13 == 0)
        y = r if trial % 2 else np.where(mask, dy, 0.0)  # post-fit residuals, or the pre-fit ones (the same separations)
        p_const = 1e-4 if trial % 4 == 1 else 1e-8  # 1e-4 (ARAIM's for a constellation without a commitment): monitored
        args = (H, sigma, mask, y, clock_columns(H, mask), geometry, 5e-5, 5e-3, p_sat, p_const)
        closed, direct = solution_separation(*args), solution_separation(*args, closed_form=False)
        assert np.array_equal(closed.n_modes, direct.n_modes) and np.array_equal(closed.enough, direct.enough)
        assert np.array_equal(closed.p_nm, direct.p_nm)
        ok = direct.enough
        well = ok & (np.where(mask & (geometry.redundancy > 0), geometry.redundancy, np.inf).min(axis=1) > 1e-3)
        tolerance = np.where(well, 1e-9, 1e-6)[ok]  # a redundancy near 0: both solutions lose digits
        np.testing.assert_array_less(np.abs(closed.hpl_m[ok] - direct.hpl_m[ok]) / direct.hpl_m[ok], tolerance + 1e-300)
        # the ratio divides two separations: twice the rounding of either
        np.testing.assert_array_less(np.abs(closed.max_ratio[ok] - direct.max_ratio[ok]),
                                     2 * tolerance * np.maximum(direct.max_ratio[ok], 1e-6) + 1e-300)  # fmt: skip
        for e in np.flatnonzero(ok & (closed.worst_slot != direct.worst_slot)):  # only ties may differ: the same separation
            assert abs(closed.max_ratio[e] - direct.max_ratio[e]) <= 1e-6 * direct.max_ratio[e]
        compared += int(ok.sum())
    assert compared > 200


@pytest.mark.parametrize("p_const", [1e-8, 1e-4])
def test_constellation_subsets_no_mode_monitors_are_not_solved_and_change_nothing(monkeypatch, p_const):
    """A constellation's subset is solved only where its mode is monitored or one of its satellites is alone in it
    (p_const 1e-8: almost nowhere): the result is bit for bit the one with every constellation's subset solved."""
    import tollcli.integrity.solution_separation as ss

    rng = np.random.default_rng(11)
    original_terms, original_one = ss._subset_terms, ss._one_constellation
    solved = {"skipping": 0, "every": 0}
    run = ["skipping"]

    def counting(*args):  # (c, n_const, g, weighted, n_used, has, at, group, Ah, var, r, rows, k, out)
        solved[run[0]] += len(args[11])
        return original_one(*args)

    def every(*args):  # the constellations' monitoring dropped: every subset solved at every epoch
        return original_terms(*args[:-1], None)

    monkeypatch.setattr(ss, "_one_constellation", counting)
    for trial in range(40):
        H, sigma, mask, r, geometry, _ = random_epochs(rng, 30, int(rng.integers(5, 30)), int(rng.integers(2, 4)),
                                                       lone=trial % 3 == 0, flat=False)  # fmt: skip
        args = (H, sigma, mask, r, clock_columns(H, mask), geometry, 5e-5, 5e-3, 1e-5, p_const)
        run[0] = "skipping"
        skipping = ss.solution_separation(*args)
        run[0] = "every"
        with monkeypatch.context() as m:
            m.setattr(ss, "_subset_terms", every)
            full = ss.solution_separation(*args)
        for field in ss.SeparationResult.__dataclass_fields__:
            a, b = getattr(skipping, field), getattr(full, field)
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), (trial, field)
    if p_const == 1e-8:  # only the constellations of lone satellites were solved, at their epochs
        assert 0 < solved["skipping"] < solved["every"] / 3
    else:  # monitored: each constellation wherever it is used beside another (not where it is absent or alone)
        assert 0.9 * solved["every"] < solved["skipping"] < solved["every"]


def test_a_fault_is_found_on_the_faulty_satellite():
    """A 60 m bias on one satellite of a good geometry: the closed form detects it and names that satellite."""
    rng = np.random.default_rng(7)
    H, sigma, mask, _, geometry, _ = random_epochs(rng, 50, 12, 2, lone=False, flat=False)
    sigma[:] = 3.0
    mask[:] = True
    geometry = wls_geometry(H, sigma, mask)
    dy = rng.normal(0, 3.0, (50, 12))
    dy[:, 5] += 60.0
    r, _ = post_fit_residuals(H, geometry, mask, dy, None)
    res = solution_separation(H, sigma, mask, np.nan_to_num(r), clock_columns(H, mask), geometry, 5e-5, 5e-3)
    found = res.max_ratio > 1.0
    assert found.mean() > 0.8 and (res.worst_slot[found] == 5).mean() > 0.9


def test_the_protection_level_is_the_least_within_the_budget():
    """The solver's L spends the integrity budget: the risk at L is within it, and at L less one part in 10⁹ it is
    not (the solver ends within 1e-10 of it: ``tests/test_protection_level_solve.py``)."""
    from tollcli.integrity.solution_separation import _risk_and_slope, _solve_hpl, radius_factor

    def _risk(hpl, *terms):
        return _risk_and_slope(hpl, *terms, True)[0]

    rng = np.random.default_rng(3)
    n_epochs, n_modes = 3000, 30
    sigma_0 = rng.uniform(0.5, 20.0, n_epochs)
    sigma_k = sigma_0[:, None] * rng.uniform(1.0, 3.0, (n_epochs, n_modes))
    prior = np.where(rng.random((n_epochs, n_modes)) < 0.8, 10.0 ** rng.uniform(-7, -4.5, (n_epochs, n_modes)), 0.0)
    threshold = radius_factor(1e-3) * sigma_k * rng.uniform(0.1, 1.0, (n_epochs, n_modes))
    budget = np.full(n_epochs, 1e-4)
    hpl = _solve_hpl(sigma_0, prior, threshold, sigma_k, budget)
    assert np.isfinite(hpl).all()
    assert (_risk(hpl, sigma_0, prior, threshold, sigma_k) <= budget).all()
    assert (_risk(hpl * (1 - 1e-9), sigma_0, prior, threshold, sigma_k) > budget).all()
