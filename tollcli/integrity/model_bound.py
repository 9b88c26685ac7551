"""A covariance-only protection level from the used satellites' geometry and an error model (no fault detection).

HPL = K_H(P_MD) · σ_major, σ_major the semi-major axis of the WLS horizontal position covariance
(A Σ Aᵀ)_EN under the per-measurement σ's, K_H(P_MD) = √(−2 ln P_MD) (the radius a circular 2-D Gaussian of
σ = σ_major exceeds with probability P_MD; 4.45 at P_MD 5e-5). It bounds the error as far as the σ's bound the
real errors, and detects nothing: a fault passes it unseen. ``benchmarks/integrity_truth.py`` measures it
against truth under the nominal and the urban σ (the bound a receiver reporting only its satellites can have).
"""

from __future__ import annotations

import numpy as np

from tollcli.gnss.sigma_models import urban_sigma_m
from tollcli.gnss.wls import Gain, Geometry, gain_covariance_en
from tollcli.integrity.sources import k_h

#: σ (m) of the worst satellite a receiver can use under the nominal model (5° elevation, low latitude, single
#: frequency, a GLONASS satellite: its clock & ephemeris σ is the largest): with no satellites reported, HDOP · this
#: bounds σ_major (``tests/test_model_level.py`` derives it)
NOMINAL_WORST_SIGMA_M = 27.6


def sigma_major_m(geometry: Geometry | Gain, sigma_m: np.ndarray) -> np.ndarray:
    """σ_major (m) per epoch of a batched WLS geometry (or its gain alone) under σ (E, N); NaN where singular or empty."""
    return major_of_covariance_m(gain_covariance_en(geometry, sigma_m), geometry.singular | (geometry.n_meas == 0))


def major_of_covariance_m(cov_en_m2: np.ndarray, void: np.ndarray) -> np.ndarray:
    """σ_major (m) of east-north covariances (E, 2, 2); NaN where ``void`` (E,: singular or no measurement)."""
    de, dn, den = cov_en_m2[:, 0, 0], cov_en_m2[:, 1, 1], cov_en_m2[:, 0, 1]
    d_major = np.sqrt(0.5 * (de + dn) + np.sqrt(0.25 * (de - dn) ** 2 + den**2))
    return np.where(void, np.nan, d_major)


def model_hpl_m(geometry: Geometry | Gain, sigma_m: np.ndarray, p_md: float) -> np.ndarray:
    """K_H(P_MD) · σ_major per epoch (m)."""
    return k_h(p_md) * sigma_major_m(geometry, sigma_m)


def hdop_hpl_m(hdop: np.ndarray, p_md: float, open_sky: np.ndarray) -> np.ndarray:
    """K_H(P_MD) · HDOP · σ_worst per epoch (m): the model bound of a fix whose satellites' geometry is not reported
    (no satellites, none used, or none with its angles: :func:`tollcli.integrity.run.no_geometry`).

    σ_major ≤ HDOP · max σᵢ (the covariance under equal σ's, scaled by the largest); σ_worst is
    :data:`NOMINAL_WORST_SIGMA_M` where ``open_sky``, its urban σ elsewhere. NaN where there is no HDOP."""
    worst = np.where(open_sky, NOMINAL_WORST_SIGMA_M, float(urban_sigma_m(NOMINAL_WORST_SIGMA_M)))
    h = np.asarray(hdop, dtype=float)
    return np.where(np.isfinite(h) & (h > 0) & (h < 99), k_h(p_md) * h * worst, np.nan)
