"""The solution separation's integrity equation solved for the protection level (``_solve_hpl``): Newton's steps
inside a bracket against plain bisection to the limit of the arithmetic, on random equations (the terms of 1–60
fault modes, σ's and thresholds over three decades, zero and missing terms) and on the real ones of a u-blox drive."""

from __future__ import annotations

import numpy as np
import pytest

from tollcli.integrity import solution_separation as ss


def _bisection(sigma_0, prior, threshold, sigma_k, budget, iterations=200):
    """The reference: bisection on [0, an L that surely suffices] until the arithmetic stops it; its upper end."""
    n_modes = np.maximum((prior > 0).sum(axis=1), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = budget / (n_modes + 1.0)
        hi = np.fmax(ss.radius_factor(share) * sigma_0,
                     np.fmax.reduce(np.where(prior > 0, threshold + ss.radius_factor(np.minimum(share[:, None] / np.where(prior > 0, prior, 1.0), 1.0))
                                             * sigma_k, 0.0), axis=1, initial=0.0))  # fmt: skip
    ok = (budget > 0) & np.isfinite(hi)
    hi = np.where(ok, hi, 0.0)
    lo = np.zeros_like(hi)
    finite = ss._finite_modes(prior, threshold, sigma_k)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        fits = ss._risk_and_slope(mid, sigma_0, prior, threshold, sigma_k, finite)[0] <= budget
        hi, lo = np.where(fits, mid, hi), np.where(fits, lo, mid)
    return np.where(ok, hi, np.nan)


def _equations(rng, n_epochs, n_modes, gaps=False):
    sigma_0 = 10 ** rng.uniform(-0.5, 1.5, n_epochs)
    sigma_k = sigma_0[:, None] * 10 ** rng.uniform(0.0, 0.7, (n_epochs, n_modes))
    threshold = 10 ** rng.uniform(-0.5, 2.0, (n_epochs, n_modes))
    prior = np.where(rng.random((n_epochs, n_modes)) < 0.8, 10 ** rng.uniform(-9, -3, (n_epochs, n_modes)), 0.0)
    budget = 10 ** rng.uniform(-9, -3, n_epochs)
    if gaps:  # what a block of real epochs holds beside: no fault-free σ, no budget left, an unsolvable mode
        sigma_0[rng.random(n_epochs) < 0.05] = 0.0
        budget[rng.random(n_epochs) < 0.05] = 0.0
        for a, value in ((threshold, np.nan), (sigma_k, np.inf)):  # one mode of 5 % of the epochs
            rows = np.flatnonzero(rng.random(n_epochs) < 0.05)
            a[rows, rng.integers(0, n_modes, rows.size)] = value
    return sigma_0, prior, threshold, sigma_k, budget


@pytest.mark.parametrize("n_modes", [1, 5, 24, 60])
@pytest.mark.parametrize("gaps", [False, True])
def test_the_protection_level_is_within_its_budget_and_within_1e_10_of_the_exact_one(n_modes, gaps):
    rng = np.random.default_rng(n_modes * 2 + gaps)
    args = _equations(rng, 3000, n_modes, gaps)
    hpl = ss._solve_hpl(*args)
    exact = _bisection(*args)
    assert np.array_equal(np.isnan(hpl), np.isnan(exact))
    solved = np.isfinite(hpl)
    assert solved.mean() > (0.8 if gaps else 0.99)
    risk = ss._risk_and_slope(np.where(solved, hpl, 0.0), *args[:4], ss._finite_modes(*args[1:4]))[0]
    assert (risk[solved] <= args[4][solved]).all(), "never a level the budget does not cover"
    assert (hpl[solved] >= exact[solved] * (1 - 1e-15)).all(), "never below the exact level"
    # (a root at 0 — no fault-free σ, every mode's prior within the budget — is found to a nanometre)
    assert (hpl[solved] - exact[solved] <= ss.HPL_REL_TOL * hpl[solved] * 1.01 + 1e-9).all()


def test_newton_needs_a_handful_of_evaluations(monkeypatch):
    """The point of Newton's steps: the whole block is done in about seven evaluations of the risk, not bisection's 48
    (the real epochs of a replayed u-blox drive behave as these)."""
    calls = []
    original = ss._risk_and_slope
    monkeypatch.setattr(ss, "_risk_and_slope", lambda *a: calls.append(1) or original(*a))
    hpl = ss._solve_hpl(*_equations(np.random.default_rng(7), 512, 40))
    assert np.isfinite(hpl).all() and len(calls) <= 16


def test_an_epochs_level_is_the_same_in_any_block():
    """Metamorphic: an epoch's level does not depend on the epochs solved with it, nor on the empty mode columns a
    block pads its rows with (its most satellites), to the bit — a log's invoice is the same in any chunks. (Newton's
    steps carry the risk's last bit into the next L: the rows are summed term after term, so a zero adds nothing.)"""
    rng = np.random.default_rng(11)
    sigma_0, prior, threshold, sigma_k, budget = _equations(rng, 400, 30)
    whole = ss._solve_hpl(sigma_0, prior, threshold, sigma_k, budget)
    rows = np.arange(0, 400, 7)
    alone = ss._solve_hpl(sigma_0[rows], prior[rows], threshold[rows], sigma_k[rows], budget[rows])
    assert np.array_equal(whole[rows], alone)
    pad = rng.integers(1, 40)
    at = np.sort(rng.integers(0, 31, pad))  # empty modes anywhere among the others, as a larger block's slots
    padded = [np.insert(a, at, fill, axis=1) for a, fill in ((prior, 0.0), (threshold, 0.0), (sigma_k, 1.0))]
    assert np.array_equal(ss._solve_hpl(sigma_0, padded[0], padded[1], padded[2], budget), whole)


@pytest.mark.parametrize("shape", [(1, 1), (3, 7), (4880, 24), (50, 214), (9, 0)])
def test_the_rows_are_summed_left_to_right(shape):
    """Known answer: each row's sum is that of adding its terms one after another (the running sum's last value), to
    the bit, over terms spanning twenty decades — whatever the block's rows and width (what the metamorphic test above
    rests on)."""
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    a = rng.normal(size=shape) * 10 ** rng.uniform(-10, 10, shape)
    expected = np.zeros(shape[0])
    for k in range(shape[1]):
        expected = expected + a[:, k] if k else a[:, 0].copy()
    assert np.array_equal(ss._row_sums(a), expected)
