"""Small pure coordinate converters (pymap3d style), WGS-84, numpy broadcasting.

Angles in degrees, lengths in metres.
"""

from __future__ import annotations

import numpy as np

WGS84_A_M = 6_378_137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
OMEGA_EARTH_RADPS = 7.2921151467e-5


def geodetic2ecef(lat_deg, lon_deg, alt_m):
    """Geodetic (ellipsoidal height) → ECEF x, y, z."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    x = (n + alt_m) * np.cos(lat) * np.cos(lon)
    y = (n + alt_m) * np.cos(lat) * np.sin(lon)
    z = (n * (1.0 - WGS84_E2) + alt_m) * np.sin(lat)
    return x, y, z


def ecef2geodetic(x, y, z):
    """ECEF → geodetic latitude, longitude (degrees) and ellipsoidal height (m); iterative, mm-exact."""
    x, y, z = (np.asarray(v, dtype=float) for v in (x, y, z))
    with np.errstate(divide="ignore", invalid="ignore"):  # the Earth's centre has no latitude: NaN
        return _ecef2geodetic(x, y, z)


def _ecef2geodetic(x, y, z):
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(6):
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        alt = p / np.maximum(np.cos(lat), 1e-12) - n
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + alt)))
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    alt = p / np.maximum(np.cos(lat), 1e-12) - n
    return np.degrees(lat), np.degrees(lon), alt


def enu_rotation(lat_deg, lon_deg) -> np.ndarray:
    """(..., 3, 3) rotation taking ECEF vectors to local east, north, up."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    zero = np.zeros_like(sl)
    return np.stack(
        [np.stack([-so, co, zero], -1), np.stack([-sl * co, -sl * so, cl], -1), np.stack([cl * co, cl * so, sl], -1)],
        axis=-2,
    )


def enu_shift2geodetic(lat_deg, lon_deg, east_m, north_m):
    """A small horizontal shift (m) applied to a position → new latitude, longitude."""
    lat = np.radians(lat_deg)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    m = n * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return lat_deg + np.degrees(north_m / m), lon_deg + np.degrees(east_m / (n * np.cos(lat)))


def geodetic2enu(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m):
    """East, north, up (m) of positions from a reference position (pymap3d's ``geodetic2enu``; broadcasts: one
    reference for all, or one per position)."""
    d = np.stack(geodetic2ecef(lat_deg, lon_deg, alt_m), -1) - np.stack(geodetic2ecef(lat0_deg, lon0_deg, alt0_m), -1)
    enu = np.einsum("...ij,...j->...i", enu_rotation(lat0_deg, lon0_deg), d)
    return enu[..., 0], enu[..., 1], enu[..., 2]


def geodetic2enu_shift(lat0_deg, lon0_deg, lat_deg, lon_deg):
    """The small horizontal shift (east, north; m) from one position to another: the inverse of
    :func:`enu_shift2geodetic`, with the radii of curvature at the mean latitude (exact to mm over km)."""
    lat0, lat = np.asarray(lat0_deg, float), np.asarray(lat_deg, float)
    mid = np.radians((lat0 + lat) / 2.0)
    s2 = np.sin(mid) ** 2
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s2)
    m = n * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s2)
    dlon = (np.asarray(lon_deg, float) - np.asarray(lon0_deg, float) + 180.0) % 360.0 - 180.0
    return np.radians(dlon) * n * np.cos(mid), np.radians(lat - lat0) * m


def great_circle_distance_m(lat1_deg, lon1_deg, lat2_deg, lon2_deg):
    """Great-circle distance (haversine on the WGS-84 equatorial radius), metres."""
    p1, p2 = np.radians(lat1_deg), np.radians(lat2_deg)
    dp, dl = p2 - p1, np.radians(np.asarray(lon2_deg) - np.asarray(lon1_deg))
    h = np.sin(dp / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * WGS84_A_M * np.arcsin(np.sqrt(np.clip(h, 0.0, 1.0)))
