"""GLONASS satellite positions and clocks from broadcast ephemerides (GLONASS ICD 5.1, A.3.1.2), vectorized.

A GLONASS ephemeris is not Keplerian: it gives the satellite's PZ-90 position, velocity and the lunisolar
acceleration at its reference time t_b (every 30 minutes). The position at t is the equations of motion (the
Earth's central field, its J2 term, the frame's rotation and the constant lunisolar acceleration) integrated from t_b
by fourth-order Runge–Kutta in steps of :data:`STEP_S` (the ICD's method; RTKLIB's ``geph2pos`` does the same). The
clock offset is −τ_n + γ_n (t − t_b). Times are GPS seconds; the ephemeris table (``glonass_strings``, or a RINEX
file) carries t_b as ``toe_s`` and, in metres, ``X``/``Y``/``Z``, ``dX``/``dY``/``dZ`` (m/s), ``dX2``/``dY2``/``dZ2``
(m/s²), ``SVclockBias`` (−τ_n, s) and ``SVrelFreqBias`` (γ_n). Every query is stepped at once.
"""

from __future__ import annotations

import numpy as np

MU_GLO = 3.9860044e14  # m³/s², PZ-90
J2_GLO = 1.0826257e-3
RE_GLO = 6_378_136.0  # m
OMEGA_GLO = 7.292115e-5  # rad/s
#: the integration step (s)
STEP_S = 60.0
#: the farthest from t_b an ephemeris is used (s): GLONASS broadcasts a new one every 30 minutes
MAX_AGE_S = 1800.0
GLONASS_FIELDS = ("X", "Y", "Z", "dX", "dY", "dZ", "dX2", "dY2", "dZ2", "SVclockBias", "SVrelFreqBias")


def _derivative(x: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """d/dt of the states (n, 6: position m, velocity m/s) in the rotating PZ-90 frame."""
    pos, vel = x[:, :3], x[:, 3:]
    r2 = (pos**2).sum(axis=1)
    r3 = r2 * np.sqrt(r2)
    a = 1.5 * J2_GLO * MU_GLO * RE_GLO**2 / r2 / r3
    b = 5.0 * pos[:, 2] ** 2 / r2
    c = -MU_GLO / r3 - a * (1.0 - b)
    w2 = OMEGA_GLO**2
    out = np.empty_like(x)
    out[:, :3] = vel
    out[:, 3] = (c + w2) * pos[:, 0] + 2.0 * OMEGA_GLO * vel[:, 1] + acc[:, 0]
    out[:, 4] = (c + w2) * pos[:, 1] - 2.0 * OMEGA_GLO * vel[:, 0] + acc[:, 1]
    out[:, 5] = (c - 2.0 * a) * pos[:, 2] + acc[:, 2]
    return out


def _rk4(x: np.ndarray, step: np.ndarray, acc: np.ndarray) -> np.ndarray:
    h = step[:, None]
    k1 = _derivative(x, acc)
    k2 = _derivative(x + k1 * h / 2.0, acc)
    k3 = _derivative(x + k2 * h / 2.0, acc)
    k4 = _derivative(x + k3 * h, acc)
    return x + (k1 + 2.0 * k2 + 2.0 * k3 + k4) * h / 6.0


def glonass_position_clock(eph: dict[str, np.ndarray], t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ECEF (PZ-90) position (n, 3) in m and clock offset (s) at GPS seconds ``t_s`` (n,), from per-query ephemeris
    arrays (:data:`GLONASS_FIELDS` and ``toe_s``). NaN where a query has no GLONASS ephemeris."""
    dt = np.asarray(t_s, float) - eph["toe_s"]
    clock = eph["SVclockBias"] + eph["SVrelFreqBias"] * dt
    x = np.stack([eph[k] for k in ("X", "Y", "Z", "dX", "dY", "dZ")], axis=1).astype(float)
    acc = np.stack([eph[k] for k in ("dX2", "dY2", "dZ2")], axis=1).astype(float)
    remaining = np.where(np.isfinite(dt) & np.isfinite(x).all(axis=1), dt, 0.0)
    while True:
        active = np.abs(remaining) > 1e-9
        if not active.any():
            break
        step = np.where(active, np.clip(remaining, -STEP_S, STEP_S), 0.0)
        x = np.where(active[:, None], _rk4(x, step, acc), x)
        remaining = remaining - step
    pos = np.where(np.isfinite(dt)[:, None], x[:, :3], np.nan)
    return pos, clock
