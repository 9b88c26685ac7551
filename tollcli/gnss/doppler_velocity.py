"""Receiver velocity and clock drift from Doppler (pseudorange rates), by batched WLS over epochs.

For measurement i with line of sight u_i (unit, receiver → satellite, ECEF), satellite velocity v_s,i
and clock drift ḋ_s,i (s/s), the measured pseudorange rate is

    ρ̇_i = (v_s,i − v) · u_i + c·(ḋ − ḋ_s,i) + ε_i,     ε_i ~ N(0, σ_i²)

so the corrected rate  y_i = ρ̇_i − v_s,i·u_i + c·ḋ_s,i = −u_i·v + c·ḋ  is linear in the unknowns
[v_east, v_north, v_up, c·ḋ] (one clock drift: one oscillator for every constellation and signal).
The WLS gives the velocity in east-north-up (m/s) at the receiver's position, its covariance
(HᵀWH)⁻¹, the horizontal speed and its 1σ: along the direction of travel when moving, the RMS of
the east and north σ at a standstill (the speed's error is then not Gaussian but its scale is this).
Rates whose post-fit residual exceeds ``OUTLIER_SIGMAS``·σ are dropped once (a cycle slip or a
multipath spike on a phone) and the fit repeated.
"""

from __future__ import annotations

import numpy as np

from tollcli.gnss.wls import wls_geometry

OUTLIER_SIGMAS = 5.0
#: below this speed (m/s) the direction of travel is undefined: σ of the speed from both axes
STANDSTILL_MPS = 0.5


def doppler_velocity(los_enu: np.ndarray, los_ecef: np.ndarray, sat_vel_mps: np.ndarray, sat_drift_mps: np.ndarray,
                     prr_mps: np.ndarray, prr_sigma_mps: np.ndarray, mask: np.ndarray) -> dict[str, np.ndarray]:  # fmt: skip
    """Velocity per epoch from (E, N) pseudorange rates.

    ``los_enu``/``los_ecef`` (E, N, 3): receiver → satellite unit vectors; ``sat_vel_mps`` (E, N, 3) ECEF;
    ``sat_drift_mps`` (E, N): c·ḋ_s; ``prr_sigma_mps`` (E, N) 1σ; ``mask`` (E, N) usable rates.
    Returns ``vel_enu_mps`` (E, 3), ``clock_drift_mps`` (E,), ``cov`` (E, 4, 4), ``speed_mps``,
    ``speed_sigma_mps``, ``course_deg``, ``n_doppler`` (E,) — NaN where fewer than 5 rates.
    """
    mask = mask & np.isfinite(prr_mps) & np.isfinite(prr_sigma_mps) & (prr_sigma_mps > 0)
    mask = mask & np.isfinite(sat_vel_mps).all(axis=-1) & np.isfinite(sat_drift_mps)
    y = np.where(mask, prr_mps - np.einsum("enk,enk->en", np.nan_to_num(sat_vel_mps), los_ecef)
                 + np.nan_to_num(sat_drift_mps), 0.0)  # fmt: skip
    H = np.concatenate([-los_enu, np.ones(mask.shape + (1,))], axis=-1)
    sigma = np.where(mask, prr_sigma_mps, np.nan)
    for attempt in range(3):
        geom = wls_geometry(H, sigma, mask)
        x = np.einsum("eun,en->eu", geom.A, y)
        resid = np.where(mask, y - np.einsum("enu,eu->en", H, x), 0.0)
        scaled = np.abs(resid) / np.where(mask, sigma, 1.0)
        outlier = mask & (scaled > OUTLIER_SIGMAS) & (mask.sum(axis=1) > 5)[:, None]
        if attempt == 2 or not outlier.any():
            break
        # drop the worst rate of each epoch that has an outlier, and fit again
        worst = np.argmax(np.where(outlier, scaled, -1.0), axis=1)
        drop = np.zeros_like(mask)
        drop[np.arange(mask.shape[0]), worst] = outlier.any(axis=1)
        mask = mask & ~drop
        sigma = np.where(mask, sigma, np.nan)
    A = geom.A
    cov = np.einsum("eun,en,evn->euv", A, np.where(mask, sigma, 0.0) ** 2, A)
    n = mask.sum(axis=1)
    ok = (n >= 5) & ~geom.singular
    ve, vn = x[:, 0], x[:, 1]
    speed = np.hypot(ve, vn)
    moving = speed > STANDSTILL_MPS
    ue, un = np.where(moving, ve / np.where(moving, speed, 1.0), 0.0), np.where(moving, vn / np.where(moving, speed, 1.0), 0.0)
    along = cov[:, 0, 0] * ue**2 + 2 * cov[:, 0, 1] * ue * un + cov[:, 1, 1] * un**2
    speed_sigma = np.sqrt(np.where(moving, along, 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])))
    nan = np.where(ok, 1.0, np.nan)
    return {
        "vel_enu_mps": x[:, :3] * nan[:, None], "clock_drift_mps": x[:, 3] * nan, "cov": cov * nan[:, None, None],
        "speed_mps": speed * nan, "speed_sigma_mps": speed_sigma * nan,
        "course_deg": np.degrees(np.arctan2(ve, vn)) % 360.0 * nan, "n_doppler": n.astype(np.int16),
    }  # fmt: skip
