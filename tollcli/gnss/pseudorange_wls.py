"""Iterated WLS positions from pseudoranges, batched over epochs (shared by GSDC and RINEX).

Satellite positions are given at transmission time in the ECEF frame of that
time; each iteration rotates them by the Earth's rotation during the flight
time (Sagnac), linearises at the current state and solves every epoch at once.
State: ECEF x, y, z and one receiver clock (m) per clock group (``clock_index``:
each measurement's group, e.g. its constellation; default one clock for all). ``correction`` (optional)
returns per-measurement delays (m) to subtract from the pseudoranges at the
current position (ionosphere, troposphere); it is applied once the solution is
near the Earth's surface.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS, ecef2geodetic, enu_rotation
from tollcli.gnss.wls import wls_geometry

C_MPS = 299_792_458.0
ITERATIONS = 12
Correction = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def sagnac(sat_xyz: np.ndarray, flight_s: np.ndarray) -> np.ndarray:
    """Rotate ECEF satellite positions by the Earth's rotation during the flight time."""
    theta = OMEGA_EARTH_RADPS * flight_s
    c, s = np.cos(theta), np.sin(theta)
    x, y, z = sat_xyz[..., 0], sat_xyz[..., 1], sat_xyz[..., 2]
    return np.stack([c * x + s * y, -s * x + c * y, z], axis=-1)


def line_of_sight(sat_xyz: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors receiver → satellite (Sagnac-corrected) and geometric ranges, (E, N, 3) and (E, N)."""
    rough = np.linalg.norm(sat_xyz - x[:, None, :3], axis=-1)
    vec = sagnac(sat_xyz, rough / C_MPS) - x[:, None, :3]
    rng = np.linalg.norm(vec, axis=-1)
    return vec / np.where(rng > 0, rng, 1.0)[..., None], rng


def local_angles(los_ecef: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Line of sight in east-north-up, elevation and azimuth (degrees)."""
    los_enu = np.einsum("eij,enj->eni", enu_rotation(lat_deg, lon_deg), los_ecef)
    elev = np.degrees(np.arcsin(np.clip(los_enu[..., 2], -1, 1)))
    azim = np.degrees(np.arctan2(los_enu[..., 0], los_enu[..., 1])) % 360.0
    return los_enu, elev, azim


def _clocks(mask: np.ndarray, clock_index: np.ndarray | None) -> tuple[np.ndarray, int]:
    if clock_index is None:
        return np.zeros(mask.shape, dtype=np.int64), 1
    return clock_index, int(clock_index[mask].max(initial=0)) + 1


def _clock_term(x: np.ndarray, clock_index: np.ndarray) -> np.ndarray:
    """Each measurement's receiver clock (m) from state ``x`` (E, 3 + C)."""
    return np.take_along_axis(x[:, 3:], np.maximum(clock_index, 0), axis=1)


def solve_positions(sat_xyz: np.ndarray, pr_m: np.ndarray, mask: np.ndarray, sigma_m: np.ndarray,
                    correction: Correction | None = None, clock_index: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Iterated WLS state (E, 3 + C): x, y, z (m, ECEF) and the receiver clocks (m)."""
    n_epochs = mask.shape[0]
    clock_index, n_clocks = _clocks(mask, clock_index)
    onehot = (clock_index[..., None] == np.arange(n_clocks)).astype(float)
    mean_sat = np.where(mask[..., None], sat_xyz, 0.0).sum(1) / np.maximum(mask.sum(1), 1)[:, None]
    norm = np.linalg.norm(mean_sat, axis=1, keepdims=True)
    x = np.concatenate([6_371_000.0 * mean_sat / np.where(norm > 0, norm, 1.0), np.zeros((n_epochs, n_clocks))], axis=1)
    for it in range(ITERATIONS):
        los, rng = line_of_sight(sat_xyz, x)
        pr = pr_m
        if correction is not None and it >= 3:
            pr = pr_m - _correction_at(correction, los, x)
        dy = np.where(mask, pr - (rng + _clock_term(x, clock_index)), 0.0)
        H = np.concatenate([-los, onehot], axis=-1)
        geom = wls_geometry(H, sigma_m, mask)
        dx = np.einsum("eun,en->eu", geom.A, dy)
        x = x + dx
        if it >= 4 and np.nanmax(np.abs(dx[:, :3]), initial=0.0) < 1e-4:
            break
    return x


def _correction_at(correction: Correction, los: np.ndarray, x: np.ndarray) -> np.ndarray:
    lat, lon, h = ecef2geodetic(x[:, 0], x[:, 1], x[:, 2])
    _, elev, azim = local_angles(los, lat, lon)
    return np.nan_to_num(correction(lat, lon, h, elev, azim))


def final_geometry(sat_xyz: np.ndarray, pr_m: np.ndarray, mask: np.ndarray, x: np.ndarray,
                   correction: Correction | None = None, clock_index: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """At the solution: geodetic position, angles, ENU observation matrix, pre-fit residuals, and the pseudoranges with
    the corrections at that position removed (``pr_m``) with their clock groups."""
    clock_index, n_clocks = _clocks(mask, clock_index)
    onehot = (clock_index[..., None] == np.arange(n_clocks)).astype(float)
    lat, lon, h = ecef2geodetic(x[:, 0], x[:, 1], x[:, 2])
    los, rng = line_of_sight(sat_xyz, x)
    los_enu, elev, azim = local_angles(los, lat, lon)
    pr = pr_m - (np.nan_to_num(correction(lat, lon, h, elev, azim)) if correction is not None else 0.0)
    dy = np.where(mask, pr - (rng + _clock_term(x, clock_index)), np.nan)
    H = np.concatenate([-los_enu, onehot], axis=-1)
    return {"lat_deg": lat, "lon_deg": lon, "height_m": h, "elev_deg": elev, "azim_deg": azim, "H": H, "dy_m": dy,
            "pr_m": np.where(mask, pr, np.nan), "clock_index": clock_index}
