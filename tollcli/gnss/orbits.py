"""Satellite positions and clocks from GPS and Galileo broadcast ephemerides (IS-GPS-200 Table 20-IV).

Vectorized over any number of (satellite, time) queries. Times are seconds
since the GPS epoch 1980-01-06 (GPS time; Galileo system time is aligned with it
to well below a microsecond for positioning). Positions are ECEF at the query
time. The clock correction includes the relativistic term and the group delay
for single-frequency L1/E1 users (GPS TGD; Galileo BGD E5b/E1 of I/NAV).
"""

from __future__ import annotations

import numpy as np

MU_GPS = 3.986005e14
MU_GAL = 3.986004418e14
OMEGA_E = 7.2921151467e-5
F_REL = -4.442807633e-10
WEEK_S = 604_800.0
HALF_WEEK_S = 302_400.0
EPHEMERIS_FIELDS = ("SVclockBias", "SVclockDrift", "SVclockDriftRate", "Crs", "DeltaN", "M0", "Cuc", "Eccentricity",
                    "Cus", "sqrtA", "Toe", "Cic", "Omega0", "Cis", "Io", "Crc", "omega", "OmegaDot", "IDOT")  # fmt: skip


def kepler_position_clock(eph: dict[str, np.ndarray], t_s: np.ndarray, galileo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ECEF position (…, 3) in m and clock offset (s) at GPS seconds ``t_s``.

    ``eph`` holds per-query arrays of the RINEX fields plus ``toc_s`` (clock
    reference time) and ``toe_s`` (ephemeris reference time), both as GPS seconds,
    and ``group_delay_s``.
    """
    mu = np.where(galileo, MU_GAL, MU_GPS)
    a = eph["sqrtA"] ** 2
    n = np.sqrt(mu / a**3) + eph["DeltaN"]
    tk = _wrap(t_s - eph["toe_s"])
    mean_anomaly = eph["M0"] + n * tk
    e = eph["Eccentricity"]
    ecc = mean_anomaly.copy()
    for _ in range(12):
        ecc = mean_anomaly + e * np.sin(ecc)
    nu = np.arctan2(np.sqrt(1 - e**2) * np.sin(ecc), np.cos(ecc) - e)
    phi = nu + eph["omega"]
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + eph["Cus"] * s2 + eph["Cuc"] * c2
    r = a * (1 - e * np.cos(ecc)) + eph["Crs"] * s2 + eph["Crc"] * c2
    i = eph["Io"] + eph["Cis"] * s2 + eph["Cic"] * c2 + eph["IDOT"] * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    toe_tow = np.mod(eph["toe_s"], WEEK_S)
    omega = eph["Omega0"] + (eph["OmegaDot"] - OMEGA_E) * tk - OMEGA_E * toe_tow
    pos = np.stack([xp * np.cos(omega) - yp * np.cos(i) * np.sin(omega),
                    xp * np.sin(omega) + yp * np.cos(i) * np.cos(omega),
                    yp * np.sin(i)], axis=-1)  # fmt: skip
    dt = _wrap(t_s - eph["toc_s"])
    clock = (eph["SVclockBias"] + eph["SVclockDrift"] * dt + eph["SVclockDriftRate"] * dt**2
             + F_REL * e * eph["sqrtA"] * np.sin(ecc) - eph["group_delay_s"])  # fmt: skip
    return pos, clock


def _wrap(dt: np.ndarray) -> np.ndarray:
    """Time differences folded into ±half a week (week crossovers)."""
    return np.where(dt > HALF_WEEK_S, dt - WEEK_S, np.where(dt < -HALF_WEEK_S, dt + WEEK_S, dt))
