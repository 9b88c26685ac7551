"""Batched weighted least squares over epochs: geometry, slopes and residuals.

Arrays are padded per epoch: ``H`` (E, N, U) observation rows, ``sigma_m``
(E, N) 1σ pseudorange errors, ``mask`` (E, N) which slots hold a measurement.
Columns of H are [east, north, up, clock_1 … clock_C]; a clock column with no
measurement in an epoch is inactive there (it does not count as an unknown).
Everything is vectorized over epochs: no Python loop per epoch.

Paper 001 eqs. 2–14: A = (HᵀΣ⁻¹H)⁻¹HᵀΣ⁻¹, B = H·A, r = (I − B)Δy,
t = rᵀΣ⁻¹r, slope_i = σ_i·√(A_E,i² + A_N,i²)/√((I − B)_ii).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

#: (I − B)_ii below this: the measurement is not checked by the others (slope ∞)
REDUNDANCY_EPS = 1e-9
#: determinant of the unit-diagonal HᵀΣ⁻¹H below which the geometry is singular
SINGULAR_RCOND = 1e-10


@dataclass
class Geometry:
    """WLS geometry of a batch of epochs (all arrays lead with the epoch axis)."""

    A: np.ndarray  # (E, U, N) WLS gain, zero columns for empty slots
    redundancy: np.ndarray  # (E, N) (I − B)_ii, 0 for empty slots
    slope: np.ndarray  # (E, N) horizontal slope, m per √λ; NaN for empty slots, inf if unchecked
    slope_max_m: np.ndarray  # (E,) largest slope (inf if some measurement is unchecked)
    n_meas: np.ndarray  # (E,) measurements
    n_unknowns: np.ndarray  # (E,) active unknowns
    dof: np.ndarray  # (E,) k = n_meas − n_unknowns
    singular: np.ndarray  # (E,) bool: the normal matrix cannot be inverted
    weight: np.ndarray  # (E, N) 1/σ², 0 for empty slots


def take_epochs(geometry: Geometry, rows: np.ndarray) -> Geometry:
    """The geometry of epochs ``rows`` (repeats allowed): every array indexed on its epoch axis."""
    return Geometry(**{f.name: getattr(geometry, f.name)[rows] for f in fields(geometry)})


def enu_rows(elev_deg: np.ndarray, azim_deg: np.ndarray) -> np.ndarray:
    """Line-of-sight rows [−e, −n, −u] (receiver→satellite unit vector, negated) for (..., N) angles."""
    el = np.radians(elev_deg)
    az = np.radians(azim_deg)
    cos_el = np.cos(el)
    return -np.stack([cos_el * np.sin(az), cos_el * np.cos(az), np.sin(el)], axis=-1)


def observation_matrix(elev_deg: np.ndarray, azim_deg: np.ndarray, clock_index: np.ndarray, n_clocks: int) -> np.ndarray:
    """H (E, N, 3 + n_clocks) from angles and each measurement's clock (constellation) column."""
    los = enu_rows(np.nan_to_num(elev_deg), np.nan_to_num(azim_deg))
    clocks = (clock_index[..., None] == np.arange(n_clocks)).astype(float)
    return np.concatenate([los, clocks], axis=-1)


def _inverse_psd(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched inverse of symmetric positive semi-definite (E, U, U); flags singular ones.

    The matrix is scaled to unit diagonal first (a correlation matrix, whose
    determinant lies in [0, 1]); a determinant below ``SINGULAR_RCOND`` marks the
    geometry singular (its inverse is returned as zeros).

    (A normal matrix of [east, north, up, clocks…] rows has a diagonal clock block, whose Schur complement
    :func:`clock_group_terms` forms: the solution separation's constellation subsets are solved through it.)
    """
    diag = np.einsum("eii->ei", G)
    scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    Gs = G * scale[:, :, None] * scale[:, None, :]
    singular = (diag <= 0).any(axis=1) | ~(np.linalg.det(Gs) > SINGULAR_RCOND)
    if singular.any():
        Gs[singular] = np.eye(G.shape[-1])
    inv = np.linalg.inv(Gs) * scale[:, :, None] * scale[:, None, :]
    inv[singular] = 0.0
    return inv, singular


@dataclass
class ClockGroups:
    """Per epoch, the measurements of each clock group (constellation) summed (:func:`clock_group_terms`)."""

    total: np.ndarray  # (E, G) Σ w: the normal matrix's clock diagonal
    centred: np.ndarray | None  # (E, N, 3) each measurement's [−e, −n, −u] row less its group's weighted mean h̄ (0 unused)
    scatter: np.ndarray  # (E, G, 3, 3) Σ w·(h − h̄)(h − h̄)ᵀ: summed over groups, the clock block's Schur complement
    squares: np.ndarray  # (E, G, 3) Σ w·h²: the position diagonal's share
    nonzero: np.ndarray  # (E, G, 3) some measurement of the group has that position entry


def clock_group_terms(Hm: np.ndarray, weight: np.ndarray, group: np.ndarray, n_groups: int, centred: bool = True) -> ClockGroups:
    """:class:`ClockGroups` of rows ``Hm`` (E, N, ≥3) with ``weight`` (E, N; 0 unused), ``group`` (E, N) each
    measurement's clock group (−1 none). The Schur complement S = P − B·D⁻¹·Bᵀ of a normal matrix's diagonal clock
    block is the sum of the groups' scatters: formed so, without the cancellation of the difference; the position
    block of the normal matrix's inverse is S⁻¹ (:func:`adjugate_inverse`), a measurement n's position gain
    S⁻¹·w_n·(h_n − h̄ of its group). Each sum is taken over the group's measurements in slot order (an epoch's terms
    do not depend on the epochs beside it). ``centred``: False leaves :attr:`ClockGroups.centred` None."""
    n_epochs, n_slots = weight.shape
    taken = np.flatnonzero((group >= 0) & (weight > 0))  # flat (epoch, slot) places, in each epoch's slot order
    key = (np.arange(n_epochs)[:, None] * n_groups + group).ravel()[taken]  # (epoch, group)
    w = weight.ravel()[taken]
    h = [np.take(Hm[..., k], taken) for k in range(3)]  # east, north, up rows: one contiguous array each
    size = n_epochs * n_groups

    def summed(values: np.ndarray) -> np.ndarray:  # Σ over each (epoch, group)'s measurements, slot after slot
        return np.bincount(key, weights=values, minlength=size).reshape(n_epochs, n_groups)

    total = summed(w)
    wh = [w * hk for hk in h]
    mean = np.stack([summed(whk) for whk in wh], axis=-1) / np.where(total > 0, total, 1.0)[..., None]  # (E, G, 3)
    d = [hk - np.take(mean[..., k], key) for k, hk in enumerate(h)]
    wd = [w * dk for dk in d]
    scatter = np.empty((n_epochs, n_groups, 3, 3))
    for i in range(3):
        for j in range(i + 1):
            scatter[..., i, j] = scatter[..., j, i] = summed(wd[i] * d[j])
    squares = np.stack([summed(whk * hk) for whk, hk in zip(wh, h)], axis=-1)
    nonzero = np.stack([summed(np.abs(hk)) for hk in h], axis=-1) > 0
    rows = None
    if centred:  # zero where no measurement is taken (its weight is zero there)
        rows = np.zeros((n_epochs * n_slots, 3))
        rows[taken] = np.stack(d, axis=-1)
        rows = rows.reshape(n_epochs, n_slots, 3)
    return ClockGroups(total, rows, scatter, squares, nonzero)


def clock_groups(Hm: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """Each used measurement's clock column (E, N; −1 unused) where every one has exactly one clock entry, a 1 (the
    form :func:`observation_matrix` writes); None otherwise."""
    if Hm.shape[-1] <= 3:
        return None
    clocks = Hm[..., 3:]
    used = weight > 0
    ones = clocks == 1.0
    if not (np.all((ones | (clocks == 0.0)) | ~used[..., None]) and np.all(ones.sum(axis=-1)[used] == 1)):
        return None
    return np.where(used, np.argmax(ones, axis=-1), -1)


def adjugate_inverse(s: np.ndarray, position_diag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of symmetric 3×3 matrices ``s`` (E, 3, 3) by their adjugate, and whether the normal matrix they are
    the Schur complement of is singular: its unit-diagonal determinant det(S) / (P₀₀·P₁₁·P₂₂) (``position_diag`` (E, 3)
    the normal matrix's position diagonal) below ``SINGULAR_RCOND`` (the inverse is then zeros)."""
    adj = np.empty_like(s)
    adj[:, 0, 0] = s[:, 1, 1] * s[:, 2, 2] - s[:, 1, 2] * s[:, 2, 1]
    adj[:, 0, 1] = s[:, 0, 2] * s[:, 2, 1] - s[:, 0, 1] * s[:, 2, 2]
    adj[:, 0, 2] = s[:, 0, 1] * s[:, 1, 2] - s[:, 0, 2] * s[:, 1, 1]
    adj[:, 1, 0] = s[:, 1, 2] * s[:, 2, 0] - s[:, 1, 0] * s[:, 2, 2]
    adj[:, 1, 1] = s[:, 0, 0] * s[:, 2, 2] - s[:, 0, 2] * s[:, 2, 0]
    adj[:, 1, 2] = s[:, 0, 2] * s[:, 1, 0] - s[:, 0, 0] * s[:, 1, 2]
    adj[:, 2, 0] = s[:, 1, 0] * s[:, 2, 1] - s[:, 1, 1] * s[:, 2, 0]
    adj[:, 2, 1] = s[:, 0, 1] * s[:, 2, 0] - s[:, 0, 0] * s[:, 2, 1]
    adj[:, 2, 2] = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0]
    det_s = s[:, 0, 0] * adj[:, 0, 0] + s[:, 0, 1] * adj[:, 1, 0] + s[:, 0, 2] * adj[:, 2, 0]
    product = position_diag[:, 0] * position_diag[:, 1] * position_diag[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        scaled_det = det_s / np.where(product > 0, product, 1.0)
    singular = (position_diag <= 0).any(axis=1) | ~(scaled_det > SINGULAR_RCOND)
    s_inv = adj / np.where(singular, 1.0, det_s)[:, None, None]
    s_inv[singular] = 0.0
    return s_inv, singular


@dataclass
class Gain:
    """The WLS gain of a batch of epochs alone (what a covariance needs; :class:`Geometry` has these and more)."""

    A: np.ndarray  # (E, U, N) WLS gain, zero columns for empty slots
    singular: np.ndarray  # (E,) bool: the normal matrix cannot be inverted
    n_meas: np.ndarray  # (E,) measurements
    weight: np.ndarray  # (E, N) 1/σ², 0 for empty slots


def _weighted_rows(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray):
    """The mask of usable measurements (a finite, positive σ), their weights 1/σ² (0 elsewhere) and H masked."""
    mask = mask & np.isfinite(sigma_m) & (sigma_m > 0)
    weight = np.where(mask, 1.0 / np.where(mask, sigma_m, 1.0) ** 2, 0.0)
    return mask, weight, np.where(mask[..., None], H, 0.0)


def _gain_terms(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray):
    """The mask of usable measurements, their weights, H masked, the active unknowns, the gain and singularity."""
    mask, weight, Hm = _weighted_rows(H, sigma_m, mask)
    active = np.abs(Hm).sum(axis=1) > 0  # (E, U)
    HwT = (Hm * weight[..., None]).transpose(0, 2, 1)  # (E, U, N) = HᵀW
    G = HwT @ Hm
    idx = np.arange(G.shape[-1])
    G[:, idx, idx] += ~active  # an inactive unknown is decoupled, not singular
    Ginv, singular = _inverse_psd(G)
    return mask, weight, Hm, active, Ginv @ HwT, singular


def wls_gain(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray) -> Gain:
    """The WLS gain of every epoch, as :func:`wls_geometry` computes it (the same numbers), without the rest."""
    mask, weight, _, _, A, singular = _gain_terms(H, sigma_m, mask)
    return Gain(A, singular, mask.sum(axis=1), weight)


def gain_covariance_en(gain: Gain | Geometry, sigma_m: np.ndarray) -> np.ndarray:
    """The east-north block (E, 2, 2; m²) of A·Σ·Aᵀ: the covariance of a WLS gain's position under σ (E, N)."""
    A = gain.A[:, :2, :]
    var = np.where(gain.weight > 0, np.nan_to_num(sigma_m), 0.0) ** 2
    return np.einsum("eun,en,evn->euv", A, var, A)


def horizontal_covariance(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The east-north block (E, 2, 2; m²) of the WLS position covariance (HᵀΣ⁻¹H)⁻¹ of every epoch, whether its
    normal matrix is singular (E,), and its measurements (E,): what :func:`wls_gain` gives through A·Σ·Aᵀ, without the
    gain. Where H's clocks are one-hot (the form :func:`observation_matrix` writes) the block is that of S⁻¹, S the
    Schur complement of the clock block (:func:`clock_group_terms`, :func:`adjugate_inverse`): a 3×3 inverse per epoch,
    not a U×U one and the N-wide products; else through the gain."""
    mask, weight, Hm = _weighted_rows(H, sigma_m, mask)
    group = clock_groups(Hm, weight)
    if group is None:
        gain = wls_gain(H, sigma_m, mask)
        return gain_covariance_en(gain, sigma_m), gain.singular, gain.n_meas
    g = clock_group_terms(Hm, weight, group, Hm.shape[-1] - 3, centred=False)
    S = g.scatter.sum(axis=1)
    active = g.nonzero.any(axis=1)  # (E, 3) the position unknowns some measurement has
    idx = np.arange(3)
    S[:, idx, idx] += ~active  # an inactive unknown is decoupled, not singular (as wls_geometry)
    s_inv, singular = adjugate_inverse(S, g.squares.sum(axis=1) + ~active)
    return s_inv[:, :2, :2], singular, mask.sum(axis=1)


def wls_geometry(H: np.ndarray, sigma_m: np.ndarray, mask: np.ndarray) -> Geometry:
    """WLS gain, redundancy, slopes and degrees of freedom for every epoch."""
    mask, weight, Hm, active, A, singular = _gain_terms(H, sigma_m, mask)
    leverage = (Hm * A.transpose(0, 2, 1)).sum(axis=-1)
    redundancy = np.where(mask, 1.0 - leverage, 0.0)
    n_meas = mask.sum(axis=1)
    n_unknowns = active.sum(axis=1)
    dof = n_meas - n_unknowns
    horiz = np.sqrt(A[:, 0, :] ** 2 + A[:, 1, :] ** 2)
    checked = redundancy > REDUNDANCY_EPS
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(checked, sigma_m * horiz / np.sqrt(np.where(checked, redundancy, 1.0)), np.inf)
    slope = np.where(mask, slope, np.nan)
    if mask.shape[1] == 0:
        slope_max = np.full(mask.shape[0], np.nan)
    else:
        slope_max = np.where(n_meas > 0, np.max(np.where(mask, slope, -np.inf), axis=1), np.nan)
    return Geometry(A, redundancy, slope, slope_max, n_meas, n_unknowns, dof, singular, weight)


def residuals_from_prefit(H: np.ndarray, geometry: Geometry, dy_m: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Post-fit residuals r = (I − B)Δy and the state correction Δx = AΔy (E, U)."""
    dy = np.where(mask, dy_m, 0.0)
    dx = np.einsum("eun,en->eu", geometry.A, dy)
    r = np.where(mask, dy - np.einsum("enu,eu->en", H, dx), np.nan)
    return r, dx


def post_fit_residuals(H: np.ndarray, geometry: Geometry, mask: np.ndarray, dy_m: np.ndarray | None,
                       residual_m: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The post-fit residuals (E, N) of a batch and the state correction (E, U) that goes with them: from
    pre-fit residuals ``dy_m`` when given (the correction from the linearisation point to this geometry's
    weighted solution), else from the receiver's own residuals at its reported position (``residual_m``: NMEA
    GRS, u-blox/gpsd prRes), else NaN.

    A receiver's residuals are those of its own solution (its weights, often a Kalman filter's): r = y − H·x_rx.
    Under this geometry's weights the solution is x_rx + A·r and its residuals (I − H·A)·r — the same as solving
    the pseudoranges afresh — so the test statistic is that of the position the RAIM vouches for, whatever the
    receiver weighted (for residuals that already are this geometry's, the projection changes nothing)."""
    if dy_m is not None:
        return residuals_from_prefit(H, geometry, dy_m, mask)
    zero = np.zeros((mask.shape[0], H.shape[-1]))
    if residual_m is not None:
        return residuals_from_prefit(H, geometry, residual_m, mask)
    return np.full(mask.shape, np.nan), zero


def wsse(residual_m: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Test statistic t = rᵀΣ⁻¹r per epoch (NaN where any used residual is missing)."""
    used = geometry.weight > 0
    missing = (used & ~np.isfinite(residual_m)).any(axis=1) | (geometry.n_meas == 0)
    t = np.where(used, geometry.weight * np.nan_to_num(residual_m) ** 2, 0.0).sum(axis=1)
    return np.where(missing, np.nan, t)
