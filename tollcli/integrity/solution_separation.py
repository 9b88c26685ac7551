"""Multiple-hypothesis solution separation (the fault-mode form of advanced RAIM), batched over epochs.

For every epoch the all-in-view WLS position x̂₀ is compared with the position of each **fault-tolerant
subset** x̂ₖ: the set without one satellite (a single-satellite fault, prior ``p_sat``), where two or more
constellations are used without one whole constellation (a constellation-wide fault, prior ``p_const``), and
— where two satellites failing at once is not negligible, ½(N·p_sat)² > p_md/4 (``--p-sat`` 1e-3 in a city,
say) — without every pair of satellites (prior p_sat²): several faults at once.
Horizontally, with Σ the measurement covariance and σ_major(C) the semi-major axis of a 2×2 covariance C:

* separation Δₖ = x̂ₖ − x̂₀ = (Aₖ − A₀)·y (east, north), its σ_ss,k = σ_major((Aₖ − A₀) Σ (Aₖ − A₀)ᵀ);
* a 2-D Gaussian of semi-major σ leaves a circle of radius K·σ with probability at most exp(−K²/2), so
  K(p) = √(−2 ln p) bounds any horizontal error at probability p (the form of the receivers' bounds,
  :func:`tollcli.integrity.sources.k_h`);
* a mode is **monitored** when its prior pₖ exceeds p_md / (2·N), N the modes present (a rarer mode could
  not take a fair share of the budget);
* test: a fault is detected when |Δₖ| > Tₖ = K(p_fa / N_mon)·σ_ss,k for a monitored mode;
* protection level: the smallest L with exp(−(L/σ₀)²/2) + Σₖ pₖ·exp(−((L − Tₖ)/σₖ)²/2) ≤ p_md − P_NM
  (σₖ = σ_major of x̂ₖ: under mode k the subset is fault-free and, with no alarm, |x̂₀ − x̂ₖ| ≤ Tₖ by the
  triangle inequality), solved for every epoch at once (:func:`_solve_hpl`: Newton's steps inside a bracket) — the
  ARAIM integrity equation with the budget going where it is needed, no fixed split;
* **faults not monitored**: P_NM, the prior probability of more satellites failing at once than any subset leaves
  out — (Σ p)² / 2 for two, (Σ p)³ / 6 for three where pairs are monitored — plus the priors of the modes too
  rare to monitor.
  Where P_NM exceeds half the budget (p_md / 2) the epoch is ``unavailable``: its HPL cannot account for the
  faults it does not exclude.

Defaults: p_sat 1e-5 (ARAIM's satellite fault prior), p_const 1e-8 (GPS's committed constellation fault
rate; ARAIM takes 1e-4 for Galileo until it commits one: ``--p-const 1e-4`` monitors constellation faults too,
at a price in HPL — a receiver's single constellation is a weak geometry).

Verdicts: ``insufficient`` (a subset would have fewer measurements than unknowns), ``unavailable``
(HPL > HAL or P_NM too large), ``fault_detected`` (a separation above its threshold), ``valid`` (none, and
HPL ≤ HAL). Everything is vectorised over epochs × subsets; there is no loop over epochs.

**No solve per subset.** A satellite or a pair left out is a low-rank update of the all-in-view solution
(:func:`_subset_terms`: with M = I − H·A and R = M[S,S], the separation is −A[:,S]·R⁻¹·r[S] and its covariance
A[:,S]·Σ_S·R⁻ᵀ·A[:,S]ᵀ). A whole constellation (and a satellite alone in its constellation: the same subset) takes
its clock with it; its subset is solved from the constellations' own sums — the Schur complement of the clock block
summed over the others, a 3×3 inverse (:func:`_constellation_terms`). Only a satellite the others barely check
(redundancy ≤ 1e-9), or a pair the update cannot take, is solved. Per (epoch, geo-object) pair the separation is not solved again: it does not depend on
the HAL (:func:`take_separation`).
The direct solve of every subset (``closed_form=False``) is kept as the reference the property test and
``benchmarks/raim_throughput.py`` compare with: the same verdicts, HPL within 1e-9 and the separation ratio within 2e-9
relative wherever every redundancy exceeds 1e-3 (1e-6 and 2e-6 nearer singular: both solutions lose digits there). Ties — two subsets separating equally, as a constellation of two satellites does — go
to the first subset (a satellite before a constellation, before a pair), not to rounding.

Why this file is long: the fault modes and their integrity equation, the subsets' terms in closed form beside the
direct solve they are tested against, detection and exclusion are one method sharing its arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.gnss.wls import REDUNDANCY_EPS, SINGULAR_RCOND, Geometry, adjugate_inverse, clock_group_terms, clock_groups, wls_geometry
from tollcli.integrity.raim import (
    FAULT,
    INSUFFICIENT,
    UNAVAILABLE,
    UNMONITORED,
    VALID,
    Detection,
)

P_SAT = 1e-5  # ARAIM's usual prior of a satellite fault per approach
P_CONST = 1e-8  # and of a constellation-wide fault
BLOCK_EPOCHS = 512  # epochs whose subsets are solved together


@dataclass
class SeparationResult:
    hpl_m: np.ndarray  # (E,) the protection level
    max_ratio: np.ndarray  # (E,) the largest |Δ| / T over subsets and axes (> 1: a fault detected)
    worst_slot: np.ndarray  # (E,) the slot whose single-satellite subset separates most (-1: a constellation or none)
    p_nm: np.ndarray  # (E,) the prior of the faults not monitored
    n_modes: np.ndarray  # (E,) fault modes monitored
    enough: np.ndarray  # (E,) every subset solvable


def radius_factor(p) -> np.ndarray:
    """K(p) = √(−2 ln p): a 2-D Gaussian of semi-major σ leaves the circle of radius K·σ with probability ≤ p."""
    return np.sqrt(-2.0 * np.log(np.clip(np.asarray(p, float), 1e-300, 1.0)))


def _finite_modes(prior: np.ndarray, threshold: np.ndarray, sigma_k: np.ndarray) -> bool:
    """Every prior and threshold finite, every σ finite and positive: :func:`_risk_and_slope` has no NaN term to guard."""
    return bool(np.isfinite(prior).all() and np.isfinite(threshold).all() and np.isfinite(sigma_k).all() and (sigma_k > 0).all())


#: the protection level is found to this share of itself (and never below the smallest L that meets the budget)
HPL_REL_TOL = 1e-10
#: evaluations of the integrity risk per epoch at most (Newton's steps converge in about seven; bisection the fallback)
HPL_MAX_STEPS = 80


def _risk_and_slope(hpl: np.ndarray, sigma_0: np.ndarray, prior: np.ndarray, threshold: np.ndarray, sigma_k: np.ndarray,
                    finite: bool) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The integrity risk at protection level ``hpl`` (E,): exp(−(L/σ₀)²/2) + Σₖ pₖ·exp(−((L − Tₖ)/σₖ)²/2), each term
    the bound on a 2-D Gaussian leaving a circle (a mode's term is pₖ while L ≤ Tₖ); and its derivative in L (E,; ≤ 0:
    each term falls as L grows). ``finite``: the caller knows every L, pₖ, Tₖ finite and every σₖ finite and positive
    (:func:`_finite_modes`) — no term is then NaN and the guards against one are skipped."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        sigma0_ok = sigma_0 > 0
        free = np.where(sigma0_ok, np.exp(-0.5 * (hpl / sigma_0) ** 2), 0.0)
        free_slope = np.where(sigma0_ok, free * hpl / sigma_0**2, 0.0)
        u = np.subtract(hpl[:, None], threshold)
        np.maximum(u, 0.0, out=u)
        np.divide(u, sigma_k, out=u)  # (L − Tₖ)⁺ / σₖ
        if not finite:
            u = np.where(np.isfinite(u), u, np.inf)
        term = np.square(u)
        np.multiply(-0.5, term, out=term)
        np.exp(term, out=term)
        np.multiply(prior, term, out=term)  # pₖ·exp(−u²/2)
        slope = np.multiply(term, u)
        np.divide(slope, sigma_k, out=slope)  # pₖ·exp(−u²/2)·u/σₖ: minus the term's derivative
        if not finite:
            term, slope = np.nan_to_num(term, nan=0.0), np.where(term > 0, slope, 0.0)
        # each row summed in column order, one term after another: a mode not present (a zero term: an empty slot, the
        # block's padding) then changes no bit, so an epoch's level is the same in any block (chunk) of epochs — Newton's
        # steps carry the last bit of the risk into the next L, where bisection only compared it with the budget
        return free + _row_sums(term), -(free_slope + _row_sums(slope))


def _row_sums(a: np.ndarray) -> np.ndarray:
    """The sums of the rows of ``a`` (E, K), each left to right (numpy's ``sum`` along a row adds in pairs: padding
    moves its partial sums). Its columns are laid out one after another and added column to column — a reduction
    over the outer axis of a contiguous array, one term after another (the last column of ``cumsum``, to the bit;
    ``tests/test_protection_level_solve.py``), without the running sums."""
    if a.shape[1] == 0:
        return np.zeros(a.shape[0])
    return np.add.reduce(np.ascontiguousarray(a.T), axis=0)


def _solve_hpl(sigma_0: np.ndarray, prior: np.ndarray, threshold: np.ndarray, sigma_k: np.ndarray,
               budget: np.ndarray) -> np.ndarray:  # fmt: skip
    """The smallest L whose integrity risk (:func:`_risk_and_slope`) is within ``budget`` (E,), for every epoch at
    once: the budget shared among the fault-free case and the monitored modes as each needs it (NaN: no L does).

    The risk falls as L grows. Each epoch keeps a bracket: ``hi`` an L within the budget (it starts at one where every
    term is at most budget / (modes + 1)), ``lo`` one beyond it (it starts at 0). The next L tried is Newton's on the
    logarithm of the risk (nearly a parabola in L: each term a Gaussian tail) from the last one tried, else the
    bracket's middle; where Newton's step is smaller than the tolerance, the L inside the bracket by half the
    tolerance (below ``hi``, or above ``lo``: the side the last L was on) is tried, which closes the bracket or moves
    its end. An epoch is done when ``hi − lo ≤`` :data:`HPL_REL_TOL` · hi, and its protection level is ``hi``: always
    within the budget, never above the exact L by more than that share. About seven evaluations instead of
    bisection's 48 (bisection to the limit of the arithmetic is the property test's reference:
    ``tests/test_protection_level_solve.py``)."""
    n_modes = np.maximum((prior > 0).sum(axis=1), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        # an L that surely suffices: every term at most budget / (modes + 1)
        share = budget / (n_modes + 1.0)
        hi_free = radius_factor(share) * sigma_0
        # (a mode whose threshold is unknown adds nothing to the risk: nor to this bound)
        hi_modes = np.fmax.reduce(np.where(prior > 0, threshold + radius_factor(np.minimum(share[:, None] / np.where(prior > 0, prior, 1.0), 1.0))
                                           * sigma_k, 0.0), axis=1, initial=0.0)  # fmt: skip
    hi = np.fmax(hi_free, hi_modes)
    ok = (budget > 0) & np.isfinite(hi)
    hi = np.where(ok, hi, 0.0)
    lo = np.zeros_like(hi)
    finite = _finite_modes(prior, threshold, sigma_k)
    log_budget = np.log(np.where(ok, budget, 1.0))
    x = hi.copy()
    active = ok & (hi > 0)
    for _ in range(HPL_MAX_STEPS):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        r, slope = _risk_and_slope(x[rows], sigma_0[rows], prior[rows], threshold[rows], sigma_k[rows], finite)
        fits = r <= budget[rows]
        lo_r, hi_r, x_r = lo[rows], hi[rows], x[rows]
        hi_r = np.where(fits, np.minimum(hi_r, x_r), hi_r)
        lo_r = np.where(fits, lo_r, np.maximum(lo_r, x_r))
        tol = HPL_REL_TOL * hi_r
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            newton = x_r - (np.log(r) - log_budget[rows]) * r / slope  # d log r / dL = r' / r
        inside = np.isfinite(newton) & (newton > lo_r) & (newton < hi_r)
        nxt = np.where(inside, newton, 0.5 * (lo_r + hi_r))
        tiny = np.isfinite(newton) & (np.abs(newton - x_r) < tol)  # converged, from either side: close the bracket
        nxt = np.where(tiny, np.where(fits, hi_r - 0.5 * tol, lo_r + 0.5 * tol), nxt)
        lo[rows], hi[rows], x[rows] = lo_r, hi_r, np.maximum(nxt, lo_r)
        active[rows] = hi_r - lo_r > tol
    return np.where(ok, hi, np.nan)


def solution_separation(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray, dy_m: np.ndarray | None,
                        clock_index: np.ndarray | None, geometry: Geometry, p_md: float, p_fa: float,
                        p_sat: float = P_SAT, p_const: float = P_CONST, closed_form: bool = True) -> SeparationResult:  # fmt: skip
    """The multiple-hypothesis solution separation of every epoch (see the module docstring).

    ``H`` (E, N, U), ``sigma_m``/``mask``/``dy_m`` (E, N): the WLS inputs (``dy_m`` the pre-fit residuals at
    the linearisation point, or None: the protection level alone, no test); ``clock_index`` (E, N): each
    measurement's constellation clock (None: one constellation). Epochs are taken ``BLOCK_EPOCHS`` at a time
    (every subset of a block at once): the working memory is a block's, whatever the batch.
    """
    n_epochs = mask.shape[0]
    pairs = (0.5 * (mask.sum(axis=1) * p_sat) ** 2 > p_md / 4.0).any()
    block = max(BLOCK_EPOCHS // max(mask.shape[1] // 2, 1), 16) if pairs else BLOCK_EPOCHS  # pairs: N/2 × the subsets
    if n_epochs > block:
        from tollcli.gnss.wls import take_epochs

        parts = []
        for a in range(0, n_epochs, block):
            rows = np.arange(a, min(a + block, n_epochs))
            parts.append(solution_separation(H[rows], sigma_m[rows], mask[rows], None if dy_m is None else dy_m[rows],
                                             None if clock_index is None else clock_index[rows], take_epochs(geometry, rows),
                                             p_md, p_fa, p_sat, p_const, closed_form))  # fmt: skip
        return SeparationResult(*(np.concatenate([getattr(p, f) for p in parts]) for f in SeparationResult.__dataclass_fields__))
    return _separation_block(H, sigma_m, mask, dy_m, clock_index, geometry, p_md, p_fa, p_sat, p_const, closed_form)


def _separation_block(H, sigma_m, mask, dy_m, clock_index, geometry: Geometry, p_md: float, p_fa: float, p_sat: float,
                      p_const: float, closed_form: bool = True) -> SeparationResult:  # fmt: skip
    n_epochs, n_slots = mask.shape
    if n_slots == 0 or n_epochs == 0:  # no satellite at all: nothing to separate
        nan, none = np.full(n_epochs, np.nan), np.zeros(n_epochs, np.int64)
        return SeparationResult(nan, nan.copy(), none - 1, np.zeros(n_epochs), none, np.zeros(n_epochs, bool))
    used = mask & (geometry.weight > 0)
    var = np.where(used, 1.0 / np.where(used, geometry.weight, 1.0), 0.0)
    const = np.zeros(mask.shape, np.int64) if clock_index is None else np.where(used, clock_index, -1)
    n_const = int(const.max(initial=0)) + 1
    n_sat = used.sum(axis=1)
    pairs_needed = 0.5 * (n_sat * p_sat) ** 2 > p_md / 4.0
    i, j = np.triu_indices(n_slots, 1) if pairs_needed.any() else (np.zeros(0, np.int64), np.zeros(0, np.int64))
    present = np.concatenate([used, np.zeros((n_epochs, n_const), bool), used[:, i] & used[:, j] & pairs_needed[:, None]], axis=1)
    const_used = np.stack([(used & (const == c)).any(axis=1) for c in range(n_const)], axis=1)
    present[:, n_slots : n_slots + n_const] = const_used & (const_used.sum(axis=1, keepdims=True) >= 2)
    kind = np.repeat([0, 1, 2], [n_slots, n_const, i.size])  # single satellite, constellation, pair of satellites
    prior = np.array([p_sat, p_const, p_sat**2])[kind][None, :] * present
    share = p_md / (2.0 * np.maximum(present.sum(axis=1), 1))[:, None]
    monitored = present & (prior > share)
    if closed_form:  # a subset no mode monitors is not solved: nothing below reads its terms
        solvable, cov_ss, cov_k, sep = _subset_terms(H, sigma_m, used, var, const, n_const, geometry, i, j, dy_m,
                                                     monitored[:, n_slots : n_slots + n_const])  # fmt: skip
    else:
        solvable, cov_ss, cov_k, sep = _subset_terms_direct(H, sigma_m, used, var, const, n_const, geometry, i, j, dy_m)
    sigma_0 = _major_of(_cov_h(geometry.A, var))
    sigma_k = _major_of(cov_k)
    sigma_ss = _major_of(cov_ss)
    enough = ~(monitored & ~solvable).any(axis=1) & (geometry.dof >= 1) & ~geometry.singular
    sigma_k = np.where(monitored, sigma_k, 1.0)
    sigma_ss = np.where(monitored, sigma_ss, 0.0)
    n_modes = monitored.sum(axis=1)
    threshold = radius_factor(p_fa / np.maximum(n_modes, 1))[:, None] * sigma_ss
    p_singles = (prior * (kind != 2)).sum(axis=1)
    p_nm = np.where(pairs_needed, p_singles**3 / 6.0, 0.5 * p_singles**2) + np.where(present & ~monitored, prior, 0.0).sum(axis=1)
    hpl = _solve_hpl(sigma_0, np.where(monitored, prior, 0.0), threshold, sigma_k, np.maximum(p_md - p_nm, 0.0))
    ratio = np.zeros(n_epochs)
    worst = np.full(n_epochs, -1, np.int64)
    if dy_m is not None:
        # a subset that cannot separate (a satellite alone in its constellation: it only fixes its own clock) has σ_ss 0,
        # computed as ~1e-14 m: its noise over its noise is no ratio
        separates = sigma_ss > SEPARATION_FLOOR * sigma_0[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(monitored & separates & (threshold > 0), np.linalg.norm(sep, axis=-1) / threshold, 0.0)
        ratio = r.max(axis=1)
        k = np.argmax(r >= ratio[:, None] * (1.0 - TIE), axis=1)  # the first within TIE of the largest: a satellite before a pair
        worst = np.where((kind[k] == 0) & (ratio > 1.0), k, -1)
    nan = ~enough
    return SeparationResult(np.where(nan, np.nan, hpl), np.where(nan, np.nan, ratio), worst, p_nm, n_modes, enough)


#: a subset whose separation's σ is below this share of the all-in-view σ does not separate (it is 0 but for rounding)
SEPARATION_FLOOR = 1e-9
#: separations within this relative difference of the largest are ties: the first subset (a satellite before a
#: constellation, before a pair) is the one excluded
TIE = 1e-9


def _cov_h(A, var):
    """The horizontal 2×2 covariance of A·y for independent y of variance ``var`` (A: (..., U, N))."""
    Ah = A[..., :2, :]
    return np.einsum("...an,...bn->...ab", Ah * var[..., None, :], Ah)


def _major_of(C):
    """Semi-major σ of 2×2 covariances (..., 2, 2)."""
    see, snn, sen = C[..., 0, 0], C[..., 1, 1], C[..., 0, 1]
    return np.sqrt(np.maximum(0.5 * (see + snn) + np.sqrt(0.25 * (see - snn) ** 2 + sen**2), 0.0))


def _subset_terms_direct(H, sigma_m, used, var, const, n_const, geometry, i, j, dy_m):
    """:func:`_subset_terms` by solving every subset (the reference the closed form is tested and timed against)."""
    n_epochs, n_slots = used.shape
    pair_drop = np.zeros((i.size, n_slots), bool)
    pair_drop[np.arange(i.size), i] = pair_drop[np.arange(i.size), j] = True
    drop = np.concatenate([np.broadcast_to(np.eye(n_slots, dtype=bool), (n_epochs, n_slots, n_slots)),
                           const[:, None, :] == np.arange(n_const)[None, :, None],
                           np.broadcast_to(pair_drop, (n_epochs, i.size, n_slots))], axis=1)  # (E, K, N)
    n_k = drop.shape[1]
    sub = wls_geometry(np.repeat(H, n_k, axis=0), np.repeat(sigma_m, n_k, axis=0), (used[:, None, :] & ~drop).reshape(-1, n_slots))
    A_k = sub.A.reshape(n_epochs, n_k, *sub.A.shape[1:])
    solvable = (~sub.singular & (sub.dof >= 0)).reshape(n_epochs, n_k)
    dA = A_k - geometry.A[:, None]
    r = np.where(used, np.nan_to_num(dy_m), 0.0) if dy_m is not None else np.zeros(used.shape)
    sep = np.einsum("ekqn,en->ekq", dA[..., :2, :], r)
    return solvable, _cov_h(dA, var[:, None, :]), _cov_h(A_k, var[:, None, :]), sep


def _subset_terms(H, sigma_m, used, var, const, n_const, geometry, i, j, dy_m, const_monitored=None):
    """Per epoch and subset (slots, constellations, pairs): solvable, the separation's horizontal covariance, the subset
    solution's horizontal covariance and the separation (east, north) — a satellite or a pair left out by the low-rank
    update of the all-in-view solution (no solve per subset), a constellation (and a subset the update cannot take:
    one leaving a clock without measurements) by solving it.

    ``const_monitored`` (E, C): the epochs whose constellation subsets a mode monitors (None: every one). A
    constellation's subset is solved there and where one of its satellites is alone in it (that satellite's subset is
    the constellation's); elsewhere its terms stay zero and unsolvable: nothing reads them (a constellation fault is
    rarely monitored — p_const 1e-8 is below its share of P_MD — so most epochs solve none).

    Leaving out S, with M = I − H·A, r = M·y the all-in-view residuals and R = M[S,S]:
    A_S − A = −A[:,S]·R⁻¹·M[S,:], the separation −A[:,S]·R⁻¹·r[S], its covariance A[:,S]·Σ_S·R⁻ᵀ·A[:,S]ᵀ (MΣ is
    symmetric) and the subset's P + that; det(G_S) = det(G)·det(R) decides its singularity as a solve would."""
    n_epochs, n_slots = used.shape
    A = geometry.A
    Ah = A[:, :2, :]  # (E, 2, N)
    Hm = np.where(used[..., None], H, 0.0)
    y = np.where(used, np.nan_to_num(dy_m), 0.0) if dy_m is not None else np.zeros(used.shape)
    if i.size:  # pairs take M's off-diagonal entries: the whole N×N
        M = np.eye(n_slots)[None] - Hm @ A  # (E, N, N)
        r = np.einsum("emn,en->em", M, y)  # the post-fit residuals (y pre-fit, or post-fit already: M·r = r)
        m = np.einsum("enn->en", M)  # (E, N) the redundancies
    else:  # a satellite alone needs M's diagonal and M·y only
        m = 1.0 - np.einsum("enu,eun->en", Hm, A)
        r = y - np.einsum("enu,eu->en", Hm, np.einsum("eun,en->eu", A, y))
    cov0 = _cov_h(A, var)
    # the normal matrix as wls_geometry forms it: its determinant and diagonal decide a subset's singularity
    weight = geometry.weight
    G = (Hm * weight[..., None]).transpose(0, 2, 1) @ Hm
    active = np.abs(Hm).sum(axis=1) > 0
    idx = np.arange(G.shape[-1])
    G[:, idx, idx] += ~active
    diag = np.einsum("eii->ei", G)
    det_g = np.linalg.det(G)
    clock_cols = H.shape[-1] - 3
    clock_count = np.stack([(used & (const == c)).sum(axis=1) for c in range(max(n_const, 1))], axis=1)  # (E, C)
    n_k = n_slots + n_const + i.size
    solvable = np.zeros((n_epochs, n_k), bool)
    cov_ss = np.zeros((n_epochs, n_k, 2, 2))
    cov_k = np.zeros((n_epochs, n_k, 2, 2))
    sep = np.zeros((n_epochs, n_k, 2))
    h2w = Hm**2 * weight[..., None]  # (E, N, U): each measurement's share of G's diagonal

    def scaled_det_ok(det_r, removed_diag):
        d = diag[..., None, :] - removed_diag if removed_diag.ndim == 3 else diag - removed_diag
        positive = d[..., 0] > 0
        product = d[..., 0].copy()
        for u in range(1, d.shape[-1]):  # the diagonal's product, column after column (as np.prod along it)
            positive &= d[..., u] > 0
            product *= d[..., u]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            scaled = det_g[..., None] * det_r / np.where(positive, product, np.nan)
        return positive & (scaled > SINGULAR_RCOND)

    # --- single satellites
    lone = used & (np.take_along_axis(clock_count, np.maximum(const, 0), axis=1) <= 1) & (clock_cols > 0)
    update = used & ~lone & (m > REDUNDANCY_EPS)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_m = np.where(update, 1.0 / np.where(update, m, 1.0), 0.0)
    a = Ah.transpose(0, 2, 1)  # (E, N, 2)
    cs = np.einsum("ena,enb->enab", a, a) * (var * inv_m)[..., None, None]
    cov_ss[:, :n_slots] = cs
    cov_k[:, :n_slots] = cov0[:, None] + cs
    sep[:, :n_slots] = -a * (r * inv_m)[..., None]
    solvable[:, :n_slots] = update & scaled_det_ok(m, h2w) & (geometry.dof[:, None] >= 1) & ~geometry.singular[:, None]
    # --- pairs
    if i.size:
        ui, uj = used[:, i], used[:, j]
        R = np.stack([np.stack([M[:, i, i], M[:, i, j]], -1), np.stack([M[:, j, i], M[:, j, j]], -1)], -2)  # (E, P, 2, 2)
        det_r = R[..., 0, 0] * R[..., 1, 1] - R[..., 0, 1] * R[..., 1, 0]
        both_lone = lone[:, i] | lone[:, j] | (const[:, i] == const[:, j]) & (np.take_along_axis(clock_count, np.maximum(const[:, i], 0), axis=1) <= 2) & (clock_cols > 0)
        ok = ui & uj & ~both_lone & (np.abs(det_r) > REDUNDANCY_EPS**2)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_det = np.where(ok, 1.0 / np.where(ok, det_r, 1.0), 0.0)
        Rinv = np.stack([np.stack([R[..., 1, 1], -R[..., 0, 1]], -1), np.stack([-R[..., 1, 0], R[..., 0, 0]], -1)], -2) * inv_det[..., None, None]
        AS = np.stack([a[:, i], a[:, j]], -1)  # (E, P, 2(axes), 2(members))
        vS = np.stack([var[:, i], var[:, j]], -1)  # (E, P, 2)
        cs = np.einsum("epam,epm,epnm,epbn->epab", AS, vS, Rinv, AS)  # A_S Σ_S R⁻ᵀ A_Sᵀ
        rS = np.stack([r[:, i], r[:, j]], -1)
        sp = -np.einsum("epam,epmn,epn->epa", AS, Rinv, rS)
        lo = n_slots + n_const
        cov_ss[:, lo:] = np.where(ok[..., None, None], cs, 0.0)
        cov_k[:, lo:] = cov0[:, None] + cov_ss[:, lo:]
        sep[:, lo:] = np.where(ok[..., None], sp, 0.0)
        removed = h2w[:, i] + h2w[:, j]
        solvable[:, lo:] = ok & scaled_det_ok(det_r, removed) & (geometry.dof[:, None] >= 2) & ~geometry.singular[:, None]
        redo_pairs = np.flatnonzero((ui & uj & ~ok).any(axis=0))
    else:
        redo_pairs = np.zeros(0, np.int64)
    # --- whole constellations, from their own normal matrices; a lone satellite's subset is its constellation's
    drops = []
    lone_e, lone_s = np.nonzero(lone)  # a lone satellite's subset is its constellation's: solved at its epochs
    needed = np.ones((n_epochs, n_const), bool) if const_monitored is None else const_monitored.copy()
    needed[lone_e, const[lone_e, lone_s]] = True
    if _constellation_terms(Hm, weight, used, const, n_const, Ah, var, r, n_slots, solvable, cov_ss, cov_k, sep, needed):
        if lone_e.size:
            e, s = lone_e, lone_s
            k = n_slots + const[e, s]
            solvable[e, s], cov_ss[e, s], cov_k[e, s], sep[e, s] = solvable[e, k], cov_ss[e, k], cov_k[e, k], sep[e, k]
        solve = used & ~update & ~lone
    else:  # clocks not one-hot: every constellation and lone satellite solved
        drops = [(n_slots + c, used & (const == c), np.ones(n_epochs, bool)) for c in range(n_const)]
        solve = used & ~update
    # --- by solving: the satellites the others barely check, the pairs the update cannot take
    for s in np.flatnonzero(solve.any(axis=0)):
        d = np.zeros(used.shape, bool)
        d[:, s] = True
        drops.append((s, d, solve[:, s]))
    for p in redo_pairs:
        d = np.zeros(used.shape, bool)
        d[:, i[p]] = d[:, j[p]] = True
        drops.append((n_slots + n_const + p, d, used[:, i[p]] & used[:, j[p]] & ~ok[:, p]))
    for k, d, rows in drops:
        rows = np.flatnonzero(rows)
        if not rows.size:
            continue
        sub = wls_geometry(H[rows], sigma_m[rows], used[rows] & ~d[rows])
        dA = sub.A - A[rows]
        solvable[rows, k] = ~sub.singular & (sub.dof >= 0)
        cov_ss[rows, k] = _cov_h(dA, var[rows])
        cov_k[rows, k] = _cov_h(sub.A, var[rows])
        sep[rows, k] = np.einsum("ean,en->ea", dA[:, :2, :], r[rows])
    return solvable, cov_ss, cov_k, sep


def _constellation_terms(Hm, weight, used, const, n_const, Ah, var, r, n_slots, solvable, cov_ss, cov_k, sep,
                         needed: np.ndarray | None = None) -> bool:  # fmt: skip
    """The terms of every constellation's subset (into the arrays, at ``n_slots + c``), as :func:`wls_geometry` would
    solve it, from the constellations' own sums (:func:`clock_group_terms`): without c, the Schur complement of the
    normal matrix's clock block is S = Σ_{c'≠c} S_c' and a kept measurement's horizontal gain is
    A[:2, n] = S⁻¹[:2]·w_n·(h_n − h̄_c(n)) — a 3×3 inverse per epoch and subset, not a U×U one and the N-wide
    products. ``needed`` (E, C): the epochs and constellations to solve (None: all; each epoch's terms are the same
    whichever others are solved with it). False (nothing written) where H's clocks are not one-hot: the caller solves."""
    n_epochs = Hm.shape[0]
    if n_const == 0 or n_epochs == 0:
        return True
    w = np.where(used, weight, 0.0)
    group = np.where(used, const, -1)
    if clock_groups(Hm, w) is None or n_const > Hm.shape[-1] - 3:
        return False
    rows = np.arange(n_epochs) if needed is None else np.flatnonzero(needed.any(axis=1))
    if rows.size == 0:
        return True
    if rows.size < n_epochs:  # the epochs some constellation's subset is needed at, alone
        Hm, w, group, used, Ah, var, r = Hm[rows], w[rows], group[rows], used[rows], Ah[rows], var[rows], r[rows]
        needed = needed[rows]
    g = clock_group_terms(Hm, w, group, n_const)
    weighted = g.centred * w[..., None]  # (E, N, 3)
    n_used = used.sum(axis=1)
    has = g.total > 0  # (E, C) clocks with measurements
    for c in range(n_const):  # a few constellations
        at = np.arange(rows.size) if needed is None else np.flatnonzero(needed[:, c])
        if at.size:
            _one_constellation(c, n_const, g, weighted[at], n_used[at], has[at], at, group[at], Ah[at], var[at], r[at],
                               rows[at], n_slots + c, (solvable, cov_ss, cov_k, sep))  # fmt: skip
    return True


def _one_constellation(c, n_const, g, weighted, n_used, has, at, group, Ah, var, r, rows, k, out) -> None:
    """Constellation ``c``'s subset at epochs ``rows`` of the block (``at``: the same epochs among ``g``'s), into
    column ``k`` of ``out`` (solvable, cov_ss, cov_k, sep)."""
    solvable, cov_ss, cov_k, sep = out
    g_scatter, g_nonzero, g_squares = g.scatter[at], g.nonzero[at], g.squares[at]
    idx = np.arange(3)
    others = np.arange(n_const) != c
    S = g_scatter[:, others].sum(axis=1)
    active = g_nonzero[:, others].any(axis=1)  # (E, 3) the position unknowns the subset still has
    S[:, idx, idx] += ~active  # an inactive unknown is decoupled, not singular (as wls_geometry)
    s_inv, singular = adjugate_inverse(S, g_squares[:, others].sum(axis=1) + ~active)
    keep = (group != c)[..., None]
    A_h = s_inv[:, :2, :] @ np.where(keep, weighted, 0.0).transpose(0, 2, 1)  # (E, 2, N) the subset's gain
    dA = A_h - Ah
    n_unknowns = active.sum(axis=1) + has[:, others].sum(axis=1)
    solvable[rows, k] = ~singular & (n_used - (group == c).sum(axis=1) - n_unknowns >= 0)
    cov_ss[rows, k] = _cov_h(dA, var)
    cov_k[rows, k] = _cov_h(A_h, var)
    sep[rows, k] = np.einsum("ean,en->ea", dA, r)


def clock_columns(H: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Each measurement's receiver-clock (constellation) column index, from H's one-hot clock columns."""
    if H.shape[-1] <= 3:
        return np.zeros(mask.shape, np.int64)
    return np.argmax(H[..., 3:], axis=-1).astype(np.int64)


def _have_residuals(mask: np.ndarray, residual_m: np.ndarray, geometry: Geometry) -> np.ndarray:
    """(E,) epochs with a residual for every used measurement."""
    used = mask & (geometry.weight > 0)
    return ~(used & ~np.isfinite(residual_m)).any(axis=1) & (geometry.n_meas > 0)


def epoch_separation(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray, residual_m: np.ndarray, geometry: Geometry,
                     params, rows: np.ndarray | None = None) -> SeparationResult:  # fmt: skip
    """:func:`solution_separation` of every epoch as :func:`separation_detection` takes it (``residual_m``: the
    all-in-view post-fit residuals, NaN where there are none: the protection level alone).

    ``rows``: solve these epochs only (each epoch's result does not depend on the others'); the rest are
    :func:`not_solved`."""
    if rows is not None:
        from tollcli.gnss.wls import take_epochs

        out = not_solved(mask.shape[0])
        if rows.size:
            part = epoch_separation(H[rows], sigma_m[rows], mask[rows], residual_m[rows], take_epochs(geometry, rows), params)
            for f in SeparationResult.__dataclass_fields__:
                getattr(out, f)[rows] = getattr(part, f)
        return out
    have = _have_residuals(mask, residual_m, geometry)
    r = np.where(mask & have[:, None], np.nan_to_num(residual_m), 0.0)
    return solution_separation(H, sigma_m, mask, r, clock_columns(H, mask), geometry, params.p_md, params.p_fa,
                               params.p_sat, params.p_const)  # fmt: skip


def not_solved(n_epochs: int) -> SeparationResult:
    """The separation of ``n_epochs`` epochs left unsolved: HPL and ratio NaN, no mode monitored, no slot."""
    nan = np.full(n_epochs, np.nan)
    return SeparationResult(nan, nan.copy(), np.full(n_epochs, -1, np.int64), np.zeros(n_epochs), np.zeros(n_epochs, np.int64),
                            np.ones(n_epochs, bool))  # fmt: skip


def take_separation(result: SeparationResult, rows: np.ndarray) -> SeparationResult:
    """The separation of epochs ``rows`` (repeats allowed: one per epoch and geo-object)."""
    return SeparationResult(*(getattr(result, f)[rows] for f in SeparationResult.__dataclass_fields__))


def separation_detection(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray, residual_m: np.ndarray,
                         geometry: Geometry, test_stat: np.ndarray, params, hal_m,
                         separation: SeparationResult | None = None) -> tuple[Detection, np.ndarray]:  # fmt: skip
    """The RAIM verdict of every epoch by solution separation (``params.mode == "ss"``), as a :class:`Detection`.

    Returns the detection (``test_stat`` the χ² statistic t as given, ``threshold`` and ``lambda_det`` NaN: the
    test is on the separations; ``hpl_m`` the protection level) and each epoch's **separation ratio**, the
    largest normalised separation maxₖ |Δₖ| / Tₖ (the test passes at ≤ 1; for an epoch with a statistic but no
    residuals, a GST RMS, t over the χ²_k threshold at p_fa).

    ``residual_m``: the all-in-view post-fit residuals (the separations are (Aₖ − A₀)·r: the same as from the
    pre-fit ones, since every Aₖ·H = I); NaN rows: no residuals, the epoch is ``unmonitored`` with its HPL.
    ``separation``: :func:`epoch_separation` of these epochs when the caller has it (it depends on neither the HAL nor
    exclusion: one per log chunk serves the epochs and every (epoch, geo-object) pair).
    """
    n = mask.shape[0]
    hal = np.broadcast_to(np.asarray(params.hal_m if hal_m is None else hal_m, dtype=float), (n,)).copy()
    have = _have_residuals(mask, residual_m, geometry)
    chi2_only = ~have & np.isfinite(test_stat)  # a statistic without residuals (GST RMS): the χ² test at p_fa
    ss = separation if separation is not None else epoch_separation(H, sigma_m, mask, residual_m, geometry, params)
    insufficient = (geometry.dof < 1) | geometry.singular | (geometry.n_meas == 0)
    status = np.full(n, VALID, dtype=np.int8)
    ratio = np.where(have, ss.max_ratio, np.nan)
    if chi2_only.any():
        from tollcli.integrity.design import stored_classic_threshold

        k = np.maximum(geometry.dof[chi2_only], 1)
        ratio[chi2_only] = test_stat[chi2_only] / stored_classic_threshold(params.p_fa, k)
    with np.errstate(invalid="ignore"):
        status[ratio > 1.0] = FAULT
        status[~np.isfinite(ratio)] = UNMONITORED
        status[~ss.enough | ~(ss.hpl_m <= hal) | (ss.p_nm > params.p_md / 2.0)] = UNAVAILABLE
    status[insufficient] = INSUFFICIENT
    nan_if = np.where(insufficient, np.nan, 1.0)
    detection = Detection(
        dof=np.maximum(geometry.dof, 0), slope_max_m=geometry.slope_max_m * nan_if,
        test_stat=test_stat, threshold=np.full(n, np.nan), lambda_det=np.full(n, np.nan), hpl_m=ss.hpl_m * nan_if,
        hal_m=hal, p_fa=np.full(n, params.p_fa) * nan_if, status=status,
    )  # fmt: skip
    return detection, ratio * nan_if


def separation_exclusion(meas, geometry: Geometry, residual_m: np.ndarray, detection: Detection, ratio: np.ndarray,
                         params) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """FDE by solution separation: where a fault was detected, drop the satellite whose subset separates most;
    if the rest passes the whole test again (its own subsets, HPL ≤ HAL), the epoch is ``excluded_valid``.

    Updates ``detection`` and the separation ``ratio`` in place; returns the excluded satellite per epoch ('' none) and the position's
    change (E, 3) east, north, up (m) when it is dropped.
    """
    from tollcli.gnss.wls import take_epochs
    from tollcli.integrity.raim import EXCLUDED

    n = meas.mask.shape[0]
    excluded = np.full(n, "", dtype=object)
    shift = np.zeros((n, 3))
    flagged = np.flatnonzero((detection.status == FAULT) & (detection.dof >= 2))
    if flagged.size == 0:
        return excluded, shift
    H, sigma, mask = meas.H[flagged], meas.sigma_m[flagged], meas.mask[flagged]
    r = np.nan_to_num(residual_m[flagged])
    first = solution_separation(H, sigma, mask, r, clock_columns(H, mask), take_epochs(geometry, flagged),
                                params.p_md, params.p_fa, params.p_sat, params.p_const)  # fmt: skip
    rows = np.flatnonzero(first.worst_slot >= 0)
    if rows.size == 0:
        return excluded, shift
    slot = first.worst_slot[rows]
    sub_mask = mask[rows].copy()
    sub_mask[np.arange(rows.size), slot] = False
    sub_geom = wls_geometry(H[rows], sigma[rows], sub_mask)
    # the subset's own residuals: r₍ⱼ₎ = r − H·Δx, Δx = A₍ⱼ₎·r (the all-in-view residuals re-fitted)
    r_rows = np.where(sub_mask, r[rows], 0.0)
    dx = np.einsum("eun,en->eu", sub_geom.A, r_rows)
    sub_r = np.where(sub_mask, r_rows - np.einsum("enu,eu->en", H[rows], dx), np.nan)
    sub_t = np.where(sub_mask, sub_geom.weight * np.nan_to_num(sub_r) ** 2, 0.0).sum(axis=1)
    again, again_ratio = separation_detection(H[rows], sigma[rows], sub_mask, sub_r, sub_geom, sub_t, params,
                                    detection.hal_m[flagged[rows]])  # fmt: skip
    ok = again.status == VALID
    epochs = flagged[rows[ok]]
    excluded[epochs] = meas.sv[epochs, slot[ok]]
    shift[epochs] = dx[ok, :3]
    for name in ("dof", "slope_max_m", "test_stat", "threshold", "hpl_m"):
        getattr(detection, name)[epochs] = getattr(again, name)[ok]
    ratio[epochs] = again_ratio[ok]
    detection.status[epochs] = EXCLUDED
    return excluded, shift
