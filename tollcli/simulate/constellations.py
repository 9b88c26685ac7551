"""Nominal satellite constellations as Walker patterns, and their ECEF positions over time.

Circular orbits (the nominal constellations are near-circular; the simulator needs
the geometry, not ephemeris-grade orbits):

* GPS: the baseline 24-slot constellation of the GPS SPS Performance Standard
  (2008, Table 3.2-1): 6 planes 60° apart, 4 unevenly spaced slots each,
  inclination 55°, semi-major axis 26 561.75 km — half a sidereal day, so the ground
  track repeats every day as the real one does (the standard's rounded 26 559.7 km
  would drift 5 s a day) (``gps_walker`` gives the even
  Walker 24/6/1 pattern, which sees fewer satellites at mid-latitudes);
* Galileo: 27 satellites, Walker 27/3/1 (24/3/1 plus one active spare per plane
  spaced evenly), inclination 56°, semi-major axis 29 600.318 km.

Times are seconds from the constellation's reference epoch ``t = 0``, at which
Greenwich sidereal angle is taken as zero (the simulation only needs relative geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS

MU_M3PS2 = 3.986004418e14
SIDEREAL_DAY_S = 86_164.0905
GPS_A_M = (MU_M3PS2 * (SIDEREAL_DAY_S / 2 / (2 * np.pi)) ** 2) ** (1 / 3)


@dataclass(frozen=True)
class Constellation:
    """Circular-orbit elements per satellite (arrays of length S)."""

    name: str  # constellation name as in the tables ("GPS", "Galileo")
    svid: np.ndarray  # satellite numbers
    a_m: np.ndarray  # semi-major axis
    incl_deg: np.ndarray
    raan_deg: np.ndarray  # right ascension of the ascending node at t = 0
    arg_lat_deg: np.ndarray  # argument of latitude at t = 0

    def ecef(self, t_s, per_satellite: bool = False) -> np.ndarray:
        return sat_ecef(self, t_s, per_satellite)


def walker(name: str, total: int, planes: int, phasing: int, incl_deg: float, a_m: float,
           raan0_deg: float = 0.0, u0_deg: float = 0.0) -> Constellation:  # fmt: skip
    """Walker delta pattern total/planes/phasing: evenly spaced planes and slots."""
    per_plane = total // planes
    k = np.arange(total)
    plane, slot = k // per_plane, k % per_plane
    raan = raan0_deg + 360.0 * plane / planes
    u = u0_deg + 360.0 * slot / per_plane + 360.0 * phasing * plane / total
    return Constellation(name, k + 1, np.full(total, a_m), np.full(total, incl_deg), raan % 360.0, u % 360.0)


#: SPS PS 2008 Table 3.2-1: plane RAAN (deg) and the argument of latitude (deg) of its four slots
GPS_SLOTS = {
    "A": (272.847, (268.126, 161.786, 11.676, 41.806)),
    "B": (332.847, (80.956, 173.336, 309.976, 204.376)),
    "C": (32.847, (111.876, 11.796, 339.666, 241.556)),
    "D": (92.847, (135.226, 265.446, 35.156, 167.356)),
    "E": (152.847, (197.046, 302.596, 66.066, 333.686)),
    "F": (212.847, (238.886, 345.226, 105.206, 135.346)),
}


def gps_nominal() -> Constellation:
    """The GPS baseline 24-slot constellation (satellite numbers 1–24 in slot order A1 … F4)."""
    raan = np.repeat([plane[0] for plane in GPS_SLOTS.values()], 4)
    u = np.concatenate([plane[1] for plane in GPS_SLOTS.values()])
    return Constellation("GPS", np.arange(1, 25), np.full(24, GPS_A_M), np.full(24, 55.0), raan, u)


def gps_walker() -> Constellation:
    return walker("GPS", 24, 6, 1, 55.0, GPS_A_M)


def galileo_nominal() -> Constellation:
    return walker("Galileo", 27, 3, 1, 56.0, 29_600_318.0, raan0_deg=15.0, u0_deg=5.0)


CONSTELLATIONS = {"gps": gps_nominal, "galileo": galileo_nominal}


def nominal(names: list[str]) -> list[Constellation]:
    """Constellations by lower-case name (``gps``, ``galileo``)."""
    unknown = [n for n in names if n.lower() not in CONSTELLATIONS]
    if unknown:
        raise ValueError(f"constellation {unknown[0]!r}: one of {', '.join(CONSTELLATIONS)}")
    return [CONSTELLATIONS[n.lower()]() for n in names]


def orbit_period_s(a_m) -> np.ndarray:
    """Orbital period of a circular orbit of radius ``a_m``, seconds."""
    return 2.0 * np.pi * np.sqrt(np.asarray(a_m, dtype=float) ** 3 / MU_M3PS2)


def sat_ecef(c: Constellation, t_s, per_satellite: bool = False) -> np.ndarray:
    """ECEF positions (..., S, 3) in metres at times ``t_s`` (seconds).

    ``t_s`` of any shape gives every satellite at those times; with
    ``per_satellite`` its last axis (S) is each satellite's own time.
    """
    t = np.asarray(t_s, dtype=float)
    t = t if per_satellite else t[..., None]
    n = np.sqrt(MU_M3PS2 / c.a_m**3)
    u = np.radians(c.arg_lat_deg) + n * t
    omega = np.radians(c.raan_deg) - OMEGA_EARTH_RADPS * t  # node longitude in the rotating frame
    i = np.radians(c.incl_deg)
    cu, su, co, so = np.cos(u), np.sin(u), np.cos(omega), np.sin(omega)
    x = c.a_m * (co * cu - so * su * np.cos(i))
    y = c.a_m * (so * cu + co * su * np.cos(i))
    z = c.a_m * (su * np.sin(i))
    return np.stack([x, y, z], axis=-1)


def stacked(constellations: list[Constellation]) -> tuple[np.ndarray, np.ndarray, Constellation]:
    """All satellites as one set: (constellation name per satellite, svid, merged elements)."""
    names = np.concatenate([np.full(c.svid.size, c.name, dtype=object) for c in constellations])
    merged = Constellation(
        "mixed",
        np.concatenate([c.svid for c in constellations]),
        np.concatenate([c.a_m for c in constellations]),
        np.concatenate([c.incl_deg for c in constellations]),
        np.concatenate([c.raan_deg for c in constellations]),
        np.concatenate([c.arg_lat_deg for c in constellations]),
    )
    return names, merged.svid, merged
