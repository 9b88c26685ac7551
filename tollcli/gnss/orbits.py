"""Satellite positions and clocks from GPS, Galileo and BeiDou broadcast ephemerides (IS-GPS-200 Table 20-IV;
BDS-SIS-ICD-B1I 3.0 §5.2.4).

Vectorized over any number of (satellite, time) queries. Times are seconds
since the GPS epoch 1980-01-06 (GPS time; Galileo system time is aligned with it
to well below a microsecond for positioning; BeiDou's ephemeris times are stored in GPS time too, its own seconds of
week being 14 s less). Positions are ECEF at the query
time. The clock correction includes the relativistic term and the group delay
for single-frequency L1/E1 users (GPS TGD; Galileo BGD E5b/E1 of I/NAV; BeiDou's clock is B3I's).
BeiDou uses CGCS2000's μ and Earth rotation, and its geostationary satellites (C01–C05, C59–C63) have their orbit
computed in an inertial frame tilted by −5° and rotated into the Earth's (ICD Table 5-11).
GLONASS is not Keplerian: :mod:`tollcli.gnss.glonass_orbits`.
"""

from __future__ import annotations

import numpy as np

MU_GPS = 3.986005e14
MU_GAL = 3.986004418e14
MU_BDS = 3.986004418e14
OMEGA_E = 7.2921151467e-5
OMEGA_BDS = 7.292115e-5
BDT_GPS_S = 14.0
C_MPS = 299_792_458.0
F_REL = -4.442807633e-10
WEEK_S = 604_800.0
HALF_WEEK_S = 302_400.0
EPHEMERIS_FIELDS = ("SVclockBias", "SVclockDrift", "SVclockDriftRate", "Crs", "DeltaN", "M0", "Cuc", "Eccentricity",
                    "Cus", "sqrtA", "Toe", "Cic", "Omega0", "Cis", "Io", "Crc", "omega", "OmegaDot", "IDOT")  # fmt: skip


def kepler_position_clock(eph: dict[str, np.ndarray], t_s: np.ndarray, galileo: np.ndarray, beidou: np.ndarray | None = None,
                          geostationary: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """ECEF position (…, 3) in m and clock offset (s) at GPS seconds ``t_s``.

    ``eph`` holds per-query arrays of the RINEX fields plus ``toc_s`` (clock
    reference time) and ``toe_s`` (ephemeris reference time), both as GPS seconds,
    and ``group_delay_s``. ``galileo``, ``beidou`` and ``geostationary`` (BeiDou GEO) mark the queries of those
    (default: none).
    """
    beidou = np.zeros(np.shape(t_s), bool) if beidou is None else np.asarray(beidou, bool)
    geo = beidou & (np.zeros(np.shape(t_s), bool) if geostationary is None else np.asarray(geostationary, bool))
    mu = np.where(beidou, MU_BDS, np.where(galileo, MU_GAL, MU_GPS))
    omega_e = np.where(beidou, OMEGA_BDS, OMEGA_E)
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
    toe_tow = np.mod(eph["toe_s"] - np.where(beidou, BDT_GPS_S, 0.0), WEEK_S)  # the system's own seconds of week
    omega = eph["Omega0"] + (eph["OmegaDot"] - np.where(geo, 0.0, omega_e)) * tk - omega_e * toe_tow
    pos = np.stack([xp * np.cos(omega) - yp * np.cos(i) * np.sin(omega),
                    xp * np.sin(omega) + yp * np.cos(i) * np.cos(omega),
                    yp * np.sin(i)], axis=-1)  # fmt: skip
    if geo.any():  # BeiDou GEO: the inertial orbit tilted by −5° about x, then turned by the Earth's rotation since toe
        sin5, cos5 = np.sin(np.radians(-5.0)), np.cos(np.radians(-5.0))
        sz, cz = np.sin(omega_e * tk), np.cos(omega_e * tk)
        xg, yg, zg = pos[..., 0], pos[..., 1], pos[..., 2]
        tilted = np.stack([xg * cz + yg * sz * cos5 + zg * sz * sin5,
                           -xg * sz + yg * cz * cos5 + zg * cz * sin5,
                           -yg * sin5 + zg * cos5], axis=-1)  # fmt: skip
        pos = np.where(geo[..., None], tilted, pos)
    dt = _wrap(t_s - eph["toc_s"])
    f_rel = np.where(beidou, -2.0 * np.sqrt(MU_BDS) / C_MPS**2, F_REL)  # GPS's constant for Galileo too, as before
    clock = (eph["SVclockBias"] + eph["SVclockDrift"] * dt + eph["SVclockDriftRate"] * dt**2
             + f_rel * e * eph["sqrtA"] * np.sin(ecc) - eph["group_delay_s"])  # fmt: skip
    return pos, clock


def _wrap(dt: np.ndarray) -> np.ndarray:
    """Time differences folded into ±half a week (week crossovers)."""
    return np.where(dt > HALF_WEEK_S, dt - WEEK_S, np.where(dt < -HALF_WEEK_S, dt + WEEK_S, dt))
