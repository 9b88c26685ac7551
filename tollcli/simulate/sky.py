"""Satellites as seen from a trajectory: positions at transmission, ranges, elevation and azimuth."""

from __future__ import annotations

import numpy as np

from tollcli.geodesy import geodetic2ecef
from tollcli.gnss.pseudorange_wls import C_MPS, local_angles, sagnac


def receiver_ecef(lat_deg, lon_deg, height_m) -> np.ndarray:
    """(E, 3) ECEF metres."""
    return np.stack(geodetic2ecef(np.asarray(lat_deg), np.asarray(lon_deg), np.asarray(height_m)), axis=-1)


def sky(sats, t_s: np.ndarray, lat_deg, lon_deg, height_m) -> dict[str, np.ndarray]:
    """Per epoch and satellite (E, S): transmission-time ECEF (in the frame of that time), range, angles.

    ``sats`` is anything with ``ecef(t_s, per_satellite)`` (a nominal constellation, or
    broadcast orbits); ``t_s`` are reception times on its time scale. The
    geometric range includes the Earth's rotation during the flight (Sagnac), as
    the WLS of :mod:`tollcli.gnss.pseudorange_wls` models it.
    """
    rx = receiver_ecef(lat_deg, lon_deg, height_m)
    t = np.asarray(t_s, dtype=float)
    flight = np.linalg.norm(sats.ecef(t) - rx[:, None, :], axis=-1) / C_MPS
    for _ in range(2):
        tx = sats.ecef(t[:, None] - flight, per_satellite=True)
        vec = sagnac(tx, flight) - rx[:, None, :]
        rng = np.linalg.norm(vec, axis=-1)
        flight = rng / C_MPS
    _, elev, azim = local_angles(vec / rng[..., None], np.asarray(lat_deg, float), np.asarray(lon_deg, float))
    return {"sat_xyz": tx, "range_m": rng, "elev_deg": elev, "azim_deg": azim}

