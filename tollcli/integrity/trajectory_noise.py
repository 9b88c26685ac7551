"""The pseudorange noise a log's own residuals show, for the trajectory estimator.

* :func:`postfit_residuals`: each measurement's residual at an estimated trajectory (m), every epoch at once;
* :func:`sigma_by_bin`: the residuals' spread and bias per C/N0 bin (elevation where C/N0 tells nothing,
  :func:`noise_bins`), σ = √(median² + (1.4826·MAD)²): a city's weak signals come late (reflections), so their bias
  is part of their error;
* :func:`correlation_inflation`: how much less a correlated error tells than a white one. A reflection lasts tens of
  seconds; the filter averages over time as if every epoch's error were new. The residuals' autocorrelation ρ (per
  measurement, summed over all, by FFT) gives the factor 1 + 2 Σ ρ(lag) (lags until ρ < :data:`RHO_CUT`) by which the
  variance of an average of correlated errors exceeds the white one; the σ are inflated by its square root.
* :func:`position_inflation`: the same factor for the errors as the position sees them. Satellites' errors in a
  city lean together (a street's reflections come from the same side), which no satellite's own series shows: each
  epoch's normalised residuals are solved for a position offset (least squares, one clock per constellation), and the
  offset's east and north series, each normalised by its white σ, give mean square × (1 + 2 Σ ρ). On the Berlin drive
  the offsets' mean square is 1.5–1.8 (1 if the satellites' errors were independent) and the factor 59 against the
  satellites' 40; on its part 60–190 s, 77 against 36.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tollcli.integrity.trajectory_filter import residuals
from tollcli.integrity.trajectory_inputs import TrajectoryInputs
from tollcli.stats import median

#: C/N0 bin edges (dB-Hz)
CN0_BINS_DBHZ = np.array([25.0, 30.0, 35.0, 40.0, 45.0])
#: elevation bin edges (deg), where C/N0 tells nothing
ELEVATION_BINS_DEG = np.array([15.0, 30.0, 45.0, 60.0])
#: fewest residuals a bin needs for its own σ (else the largest σ of the bins that have one)
MIN_BIN_COUNT = 20
#: the smallest σ a bin is given (m): a code measurement in a moving car is not better
SIGMA_FLOOR_M = 3.0
#: the autocorrelation below which lags stop counting
RHO_CUT = 0.05
#: the longest lag counted (epochs)
MAX_LAG = 400


def postfit_residuals(inp: TrajectoryInputs, x: np.ndarray, motion_states: int) -> np.ndarray:
    """Pseudorange minus the range from the trajectory ``x`` (E, S: ENU position first, clocks from
    ``motion_states``) minus the constellation's clock (E, N; NaN in empty slots): the ranges as the filter's pass
    takes them (:func:`tollcli.integrity.trajectory_filter.residuals`)."""
    return residuals(inp, x)


def cn0_bins(cn0_dbhz: np.ndarray) -> np.ndarray:
    """Each measurement's C/N0 bin (0 … len(CN0_BINS_DBHZ)); the last bin + 1 where C/N0 is not reported."""
    b = np.searchsorted(CN0_BINS_DBHZ, np.nan_to_num(cn0_dbhz, nan=-1.0), side="right")
    return np.where(np.isfinite(cn0_dbhz), b, CN0_BINS_DBHZ.size + 1)


def noise_bins(cn0_dbhz: np.ndarray, elev_deg: Callable[[], np.ndarray], mask: np.ndarray) -> tuple[np.ndarray, int, str]:
    """The bins the noise is measured in: C/N0 (:func:`cn0_bins`) where at least two of them hold
    :data:`MIN_BIN_COUNT` measurements, else elevation (:data:`ELEVATION_BINS_DEG`: a log without C/N0, or with one
    value for all, still tells a low satellite from a high one; ``elev_deg`` makes them, called only then).
    Returns (bins, their number, ``cn0``/``elevation``)."""
    bins = cn0_bins(cn0_dbhz)
    counts = np.bincount(bins[mask], minlength=CN0_BINS_DBHZ.size + 2)
    if (counts[: CN0_BINS_DBHZ.size + 1] >= MIN_BIN_COUNT).sum() >= 2:
        return bins, CN0_BINS_DBHZ.size + 2, "cn0"
    return np.searchsorted(ELEVATION_BINS_DEG, np.nan_to_num(elev_deg(), nan=0.0), side="right"), ELEVATION_BINS_DEG.size + 1, "elevation"


def sigma_by_bin(residual_m: np.ndarray, bins: np.ndarray, n_bins: int, mask: np.ndarray) -> np.ndarray:
    """σ (m) per bin from the residuals: √(median² + (1.4826·MAD)²), at least :data:`SIGMA_FLOOR_M`; a bin with too
    few residuals takes the largest σ of the others."""
    ok = mask & np.isfinite(residual_m)
    table = np.full(n_bins, np.nan)
    for b in range(n_bins):  # a handful of bins
        r = residual_m[ok & (bins == b)]
        if r.size >= MIN_BIN_COUNT:
            med = median(r)
            table[b] = np.hypot(med, 1.4826 * median(np.abs(r - med)))
    worst = np.nanmax(table) if np.isfinite(table).any() else 30.0
    return np.maximum(np.where(np.isfinite(table), table, worst), SIGMA_FLOOR_M)


def sigma_by_cn0(residual_m: np.ndarray, cn0_dbhz: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """:func:`sigma_by_bin` over the C/N0 bins."""
    return sigma_by_bin(residual_m, cn0_bins(cn0_dbhz), CN0_BINS_DBHZ.size + 2, mask)


def correlation_inflation(z: np.ndarray, sv: np.ndarray, mask: np.ndarray) -> tuple[float, np.ndarray]:
    """The variance factor 1 + 2 Σ ρ(lag) of normalised residuals ``z`` (E, N) and ρ itself (lags in epochs).

    Each measurement label's (``sv``: strings, or numbers in the strings' order) series (its median removed) is one time
    series; their products at every lag are summed over all series (FFT, zero where a series has no value). The series
    are transformed :data:`SERIES_AT_ONCE` at a time and their power spectra summed one after another (the sum of all at
    once, to the bit): the memory is theirs, not every satellite's times the log's length."""
    n_epochs = z.shape[0]
    ok = mask & np.isfinite(z)
    labels, inverse = _labels(sv[ok])
    if labels.size == 0 or n_epochs < 3:
        return 1.0, np.ones(1)
    rows, values = np.nonzero(ok)[0], z[ok]
    if labels.size < 1 << 15:  # (a stable sort of small numbers is a radix sort: the same order, sooner)
        inverse = inverse.astype(np.int16)
    order = np.argsort(inverse, kind="stable")  # each label's values in the log's order
    edges = np.searchsorted(inverse[order], np.arange(labels.size + 1))
    size = 1 << int(np.ceil(np.log2(n_epochs + MAX_LAG + 1)))  # zeros enough that no lag counted wraps round
    power = None
    for first in range(0, labels.size, SERIES_AT_ONCE):
        group = range(first, min(first + SERIES_AT_ONCE, labels.size))
        series = np.zeros((len(group), n_epochs))
        for row, label in enumerate(group):
            at = order[edges[label] : edges[label + 1]]
            when = rows[at]  # (the log's order)
            if when.size > 1 and not (when[1:] > when[:-1]).all():  # a label twice in an epoch: its last value counts
                value, seen = np.zeros(n_epochs), np.zeros(n_epochs, bool)
                value[when], seen[when] = values[at], True
                series[row] = np.where(seen, value - np.median(value[seen]), 0.0)
                continue
            own = values[at]
            series[row, when] = own - median(own)
        spec = np.fft.rfft(series, size, axis=1)
        for term in np.square(spec.real) + np.square(spec.imag):  # |X|², in real arithmetic: the same bits in any group
            if power is None:
                power = term.copy()
            else:
                power += term
    acf = np.fft.irfft(power, size)[: min(MAX_LAG + 1, n_epochs)]
    if not acf[0] > 0:
        return 1.0, np.ones(1)
    rho = acf / acf[0]
    return _variance_factor(rho), rho


def correlation_lags(rho: np.ndarray) -> int:
    """How many lags an autocorrelation ``rho`` stays at or above :data:`RHO_CUT` (its whole length if it does)."""
    below = np.flatnonzero(rho < RHO_CUT)
    return int(below[0]) if below.size else rho.size


def _variance_factor(rho: np.ndarray) -> float:
    """1 + 2 Σ ρ(lag) over the lags before ρ first falls below :data:`RHO_CUT`."""
    return float(1.0 + 2.0 * rho[1 : correlation_lags(rho)].sum())


def position_inflation(z: np.ndarray, inp: TrajectoryInputs, x: np.ndarray, mask: np.ndarray) -> tuple[float, np.ndarray]:
    """The variance factor of normalised residuals ``z`` (E, N) as the position sees them, and ρ of the axis that gives
    it (lags in epochs): each epoch's offset δ = (HᵀH)⁻¹Hᵀz (H: the line-of-sight rows at the trajectory ``x`` (E, S),
    ENU, and a column per clock group) where ``mask`` keeps at least two measurements more than the unknowns; per axis
    (east, north) the series δ / √((HᵀH)⁻¹) (its median removed; zero where there is no offset) gives
    mean square × (1 + 2 Σ ρ(lag)) (lags until ρ < :data:`RHO_CUT`); the larger of the two. 1 where no epoch has an
    offset."""
    n_epochs = z.shape[0]
    offsets = np.full((n_epochs, 2), np.nan)
    n_clocks = inp.n_clocks
    for first in range(0, n_epochs, OFFSET_BLOCK):
        rows = slice(first, min(first + OFFSET_BLOCK, n_epochs))
        offsets[rows] = _offsets(z[rows], mask[rows], inp.sat_ecef_m[rows], inp.clock_index[rows], x[rows, :3], inp, n_clocks)
    best, best_rho = 1.0, np.ones(1)
    for axis in range(2):
        series = offsets[:, axis]
        have = np.isfinite(series)
        if have.sum() < 3:
            continue
        series = np.where(have, series - median(series[have]), 0.0)
        size = 1 << int(np.ceil(np.log2(n_epochs + MAX_LAG + 1)))
        spec = np.fft.rfft(series, size)
        acf = np.fft.irfft(np.square(spec.real) + np.square(spec.imag), size)[: min(MAX_LAG + 1, n_epochs)]
        if not acf[0] > 0:
            continue
        rho = acf / acf[0]
        factor = float(acf[0] / have.sum()) * _variance_factor(rho)
        if factor > best:
            best, best_rho = factor, rho
    return best, best_rho


def _offsets(z, mask, sat_ecef_m, clock_index, enu_m, inp: TrajectoryInputs, n_clocks: int) -> np.ndarray:
    """(B, 2) each epoch's east and north offset solved from its normalised residuals, each over its white σ (NaN
    where the epoch has too few measurements). The clocks are taken out first: the least squares with a clock per
    group is the one without clocks on the rows less their group's mean (the clocks' block of HᵀH is diagonal), so
    HᵀH's position block is Σ u uᵀ − Σ_groups (Σ u)(Σ u)ᵀ / n and Hᵀz's is Σ u z − Σ_groups (Σ u)(Σ z) / n: a 3 × 3
    system per epoch, solved in closed form. Each component is its own (B, N) array: row sums, no small matrices."""
    keep = mask & np.isfinite(z)
    receiver = inp.origin_ecef_m + enu_m @ inp.ecef2enu
    los = [sat_ecef_m[..., k] - receiver[:, k, None] for k in range(3)]  # ECEF: the frame turned at the end
    with np.errstate(invalid="ignore", divide="ignore"):
        length = -np.sqrt(los[0] * los[0] + los[1] * los[1] + los[2] * los[2])
    rows = [np.where(keep, component / length, 0.0) for component in los]  # −u (H's rows)
    value = np.where(keep, z, 0.0)
    pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    normal = [_dot(rows[j], rows[k]) for j, k in pairs]
    rhs = [_dot(row, value) for row in rows]
    unknowns = np.full(keep.shape[0], 3)
    for group in range(n_clocks):  # a handful of constellations
        member = (keep & (clock_index == group)).astype(float)
        count = _dot(member, member)  # (a sum of ones: exact)
        unknowns += count > 0
        inverse = np.divide(1.0, count, out=np.zeros(count.shape), where=count > 0)
        sums = [_dot(row, member) for row in rows]
        total = _dot(value, member)
        for m, (j, k) in enumerate(pairs):
            normal[m] -= sums[j] * sums[k] * inverse
        for j in range(3):
            rhs[j] -= sums[j] * total * inverse
    a, b, c, e, f, i = normal
    # the inverse of the symmetric [[a, b, c], [b, e, f], [c, f, i]] by cofactors, times det
    adj = np.stack([e * i - f * f, c * f - b * i, b * f - c * e, a * i - c * c, c * b - a * f, a * e - b * b], axis=1)
    det = a * adj[:, 0] + b * adj[:, 1] + c * adj[:, 2]
    full = adj[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    scale = np.maximum(np.maximum(a, e), i)
    enough = (keep.sum(axis=1) >= unknowns + 2) & (det > 1e-12 * scale**3)
    turn = inp.ecef2enu[:2]  # east and north
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.einsum("kj,bji,bi->bk", turn, full, np.stack(rhs, axis=1)) / det[:, None]
        variance = np.einsum("kj,bji,ki->bk", turn, full, turn) / det[:, None]
        out = delta / np.sqrt(variance)
    out[~enough] = np.nan
    return out


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two (B, N) arrays."""
    return np.einsum("ij,ij->i", x, y)


#: epochs whose offsets are solved at once (:func:`position_inflation`)
OFFSET_BLOCK = 4096
#: the residual series transformed at once (:func:`correlation_inflation`)
SERIES_AT_ONCE = 16


def _labels(sv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(sv, return_inverse=True)``; for small non-negative integer codes (the estimator's factorized
    labels) by counting, without a sort."""
    if sv.dtype.kind in "iu" and sv.size and sv.min() >= 0 and sv.max() < 1 << 20:
        present = np.bincount(sv) > 0
        labels = np.flatnonzero(present).astype(sv.dtype)
        return labels, (np.cumsum(present) - 1)[sv]
    return np.unique(sv, return_inverse=True)
