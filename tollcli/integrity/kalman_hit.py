"""Multi-sensor integrity indicators of paper 004: the Kalman filter's HIT, and HPL_SBAS.

The extended Kalman filter runs the paper's vehicle model (eq. 3): state (x east, y north, φ
heading from east, v speed, ω yaw rate, a acceleration), ẋ = (v + a·t)cos φ, ẏ = (v + a·t)sin φ,
φ̇ = ω, v̇ = a, ω̇ = η_ω, ȧ = η_a (random walks). Observations: the GNSS position (σ from the
log's GST, else ``sigma_gps_m``; the paper's 3 m) and the speed over ground (the receiver's
Doppler speed standing in for the paper's odometer). No inertial sensor: ω and a are observed
only through the positions. HIT = k·√λ_max(P_xy) (eq. 5, k = 3): it keeps a bound through
outages, growing with them. A filter is sequential: this is a loop over epochs (6×6 matrices),
run on demand, not in the charging hot path.

HPL_SBAS = K_H · d_major (K_H = 6.18), d_major the semi-major axis of the WLS position covariance
from the per-satellite σ's (DO-229).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

K_H_SBAS = 6.18


@dataclass(frozen=True)
class HitParams:
    k_sigma: float = 3.0
    sigma_gps_m: float = 3.0
    sigma_speed_mps: float = 0.2
    q_yaw_accel: float = 0.01038  # rad/s² per √s: random walk of ω (paper's σ_ω_ins)
    q_jerk: float = 0.0996  # m/s³ per √s: random walk of a (paper's σ_a_ins)
    max_gap_s: float = 600.0


def _predict(x: np.ndarray, P: np.ndarray, dt: float, p: HitParams) -> tuple[np.ndarray, np.ndarray]:
    px, py, phi, v, w, a = x
    vt = v + a * dt / 2.0
    c, s = np.cos(phi + w * dt / 2.0), np.sin(phi + w * dt / 2.0)
    xn = np.array([px + vt * c * dt, py + vt * s * dt, phi + w * dt, v + a * dt, w, a])
    F = np.eye(6)
    F[0, 2], F[1, 2] = -vt * s * dt, vt * c * dt
    F[0, 3], F[1, 3] = c * dt, s * dt
    F[0, 4], F[1, 4] = -vt * s * dt * dt / 2.0, vt * c * dt * dt / 2.0
    F[0, 5], F[1, 5] = c * dt * dt / 2.0, s * dt * dt / 2.0
    F[2, 4] = dt
    F[3, 5] = dt
    Q = np.zeros((6, 6))
    # integrated random walks on ω and a (white noise on their rates)
    for i_rate, i_int, q in ((4, 2, p.q_yaw_accel**2), (5, 3, p.q_jerk**2)):
        Q[i_rate, i_rate] = q * dt
        Q[i_int, i_int] = q * dt**3 / 3.0
        Q[i_int, i_rate] = Q[i_rate, i_int] = q * dt**2 / 2.0
    return xn, F @ P @ F.T + Q


def _update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    y = z - H @ x
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(6) - K @ H
    return x + K @ y, I_KH @ P @ I_KH.T + K @ R @ K.T  # Joseph form


def hit(east_m: np.ndarray, north_m: np.ndarray, speed_mps: np.ndarray, t_s: np.ndarray,
        sigma_m: np.ndarray | None = None, params: HitParams = HitParams()) -> pd.DataFrame:  # fmt: skip
    """Filtered east/north (m, in the frame of the inputs), HIT (m) and λ_max per epoch.

    Epochs without a position (NaN) are predicted only: the outage the HIT must bridge.
    """
    n = len(t_s)
    east, north = np.asarray(east_m, float), np.asarray(north_m, float)
    speed = np.asarray(speed_mps, float)
    sig = np.full(n, params.sigma_gps_m) if sigma_m is None else np.where(np.isfinite(sigma_m) & (sigma_m > 0), sigma_m, params.sigma_gps_m)
    out = np.full((n, 4), np.nan)
    have = np.flatnonzero(np.isfinite(east) & np.isfinite(north))
    if have.size < 2:
        return pd.DataFrame(out, columns=["kf_east_m", "kf_north_m", "hit_m", "lambda_max_m2"])
    i0, i1 = have[0], have[1]
    phi0 = np.arctan2(north[i1] - north[i0], east[i1] - east[i0])
    v0 = speed[i0] if np.isfinite(speed[i0]) else 0.0
    x = np.array([east[i0], north[i0], phi0, v0, 0.0, 0.0])
    P = np.diag([sig[i0] ** 2, sig[i0] ** 2, np.radians(30.0) ** 2, 1.0, 0.01, 0.25])
    H_pos = np.zeros((2, 6))
    H_pos[0, 0] = H_pos[1, 1] = 1.0
    H_vel = np.zeros((1, 6))
    H_vel[0, 3] = 1.0
    last_t = t_s[i0]
    for k in range(i0, n):  # sequential by nature; 6×6 algebra per epoch
        dt = float(t_s[k] - last_t)
        if dt > params.max_gap_s:
            break
        if dt > 0:
            x, P = _predict(x, P, dt, params)
            last_t = t_s[k]
        if np.isfinite(east[k]) and np.isfinite(north[k]):
            x, P = _update(x, P, np.array([east[k], north[k]]), H_pos, np.eye(2) * sig[k] ** 2)
            if np.isfinite(speed[k]):
                x, P = _update(x, P, np.array([speed[k]]), H_vel, np.array([[params.sigma_speed_mps**2]]))
        Pxy = P[:2, :2]
        lam = 0.5 * (Pxy[0, 0] + Pxy[1, 1]) + np.sqrt(0.25 * (Pxy[0, 0] - Pxy[1, 1]) ** 2 + Pxy[0, 1] ** 2)
        out[k] = (x[0], x[1], params.k_sigma * np.sqrt(lam), lam)
    return pd.DataFrame(out, columns=["kf_east_m", "kf_north_m", "hit_m", "lambda_max_m2"])


def hpl_sbas_m(geometry, sigma_m: np.ndarray) -> np.ndarray:
    """K_H · d_major per epoch from a batched WLS geometry (``tollcli.gnss.wls.Geometry``) and σ (E, N)."""
    from tollcli.integrity.model_bound import sigma_major_m

    return K_H_SBAS * sigma_major_m(geometry, sigma_m)
