"""Iterated WLS positions from pseudoranges, batched over epochs (shared by GSDC and RINEX).

Satellite positions are given at transmission time in the ECEF frame of that
time; each iteration rotates them by the Earth's rotation during the flight
time (Sagnac), linearises at the current state and solves every epoch at once —
:data:`BLOCK_EPOCHS` epochs at a time, so that an iteration's (E, N, U) arrays are a block's, not a long log's
(each epoch's solution is its own: the same bits whatever the block, tested).
State: ECEF x, y, z and one receiver clock (m) per clock group (``clock_index``:
each measurement's group, e.g. its constellation; default one clock for all). ``correction`` (optional)
returns per-measurement delays (m) to subtract from the pseudoranges at the
current position (ionosphere, troposphere) of the epochs ``rows`` (a slice of the log's); it is applied once the
solution is near the Earth's surface.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tollcli.geodesy import OMEGA_EARTH_RADPS, ecef2geodetic, enu_rotation
from tollcli.gnss.wls import wls_geometry

C_MPS = 299_792_458.0
ITERATIONS = 12
#: epochs linearised and solved at once
BLOCK_EPOCHS = 4096
#: ``correction(lat_deg, lon_deg, height_m, elev_deg, azim_deg, rows)``: the delays (m) of the epochs ``rows``
Correction = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, slice], np.ndarray]


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


def solvable(mask: np.ndarray, clock_index: np.ndarray | None = None) -> np.ndarray:
    """Epochs (E,) with at least as many measurements as unknowns: the position's three and one clock per clock group
    the epoch has a measurement of (three GPS satellites and one Galileo are four measurements of five unknowns: the
    solution stays where the iteration started, hundreds of kilometres off, and is not a fix)."""
    clock_index, n_clocks = _clocks(mask, clock_index)
    present = np.zeros((mask.shape[0], n_clocks), bool)
    rows, cols = np.nonzero(mask)
    present[rows, clock_index[rows, cols]] = True
    return mask.sum(axis=1) >= 3 + present.sum(axis=1)


def blocks(n_epochs: int, size: int | None = None) -> list[slice]:
    """The epochs 0 … ``n_epochs`` in slices of ``size`` (default :data:`BLOCK_EPOCHS`)."""
    size = size or BLOCK_EPOCHS
    return [slice(a, min(a + size, n_epochs)) for a in range(0, n_epochs, size)] or [slice(0, 0)]


def solve_positions(sat_xyz: np.ndarray, pr_m: np.ndarray, mask: np.ndarray, sigma_m: np.ndarray,
                    correction: Correction | None = None, clock_index: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Iterated WLS state (E, 3 + C): x, y, z (m, ECEF) and the receiver clocks (m). Every epoch iterates until the
    largest step of any is below 0.1 mm (from the fifth iteration on), :data:`ITERATIONS` at most."""
    n_epochs = mask.shape[0]
    clock_index, n_clocks = _clocks(mask, clock_index)
    mean_sat = np.where(mask[..., None], sat_xyz, 0.0).sum(1) / np.maximum(mask.sum(1), 1)[:, None]
    norm = np.linalg.norm(mean_sat, axis=1, keepdims=True)
    x = np.concatenate([6_371_000.0 * mean_sat / np.where(norm > 0, norm, 1.0), np.zeros((n_epochs, n_clocks))], axis=1)
    for it in range(ITERATIONS):
        dx = np.empty_like(x)
        for rows in blocks(n_epochs):
            ci = clock_index[rows]
            los, rng = line_of_sight(sat_xyz[rows], x[rows])
            pr = pr_m[rows]
            if correction is not None and it >= 3:
                pr = pr - _correction_at(correction, los, x[rows], rows)
            dy = np.where(mask[rows], pr - (rng + _clock_term(x[rows], ci)), 0.0)
            H = np.concatenate([-los, (ci[..., None] == np.arange(n_clocks)).astype(float)], axis=-1)
            geom = wls_geometry(H, sigma_m[rows], mask[rows])
            dx[rows] = np.einsum("eun,en->eu", geom.A, dy)
        x = x + dx
        if it >= 4 and np.nanmax(np.abs(dx[:, :3]), initial=0.0) < 1e-4:
            break
    return x


def _correction_at(correction: Correction, los: np.ndarray, x: np.ndarray, rows: slice) -> np.ndarray:
    lat, lon, h = ecef2geodetic(x[:, 0], x[:, 1], x[:, 2])
    _, elev, azim = local_angles(los, lat, lon)
    return np.nan_to_num(correction(lat, lon, h, elev, azim, rows))


def final_geometry(sat_xyz: np.ndarray, pr_m: np.ndarray, mask: np.ndarray, x: np.ndarray,
                   correction: Correction | None = None, clock_index: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """At the solution: geodetic position, angles, ENU observation matrix, pre-fit residuals, and the pseudoranges with
    the corrections at that position removed (``pr_m``) with their clock groups (a block of epochs at a time)."""
    clock_index, n_clocks = _clocks(mask, clock_index)
    lat, lon, h = ecef2geodetic(x[:, 0], x[:, 1], x[:, 2])
    n_epochs, n_slots = mask.shape
    out = {"lat_deg": lat, "lon_deg": lon, "height_m": h, "elev_deg": np.empty((n_epochs, n_slots)),
           "azim_deg": np.empty((n_epochs, n_slots)), "H": np.empty((n_epochs, n_slots, 3 + n_clocks)),
           "dy_m": np.empty((n_epochs, n_slots)), "pr_m": np.empty((n_epochs, n_slots)), "clock_index": clock_index}  # fmt: skip
    for rows in blocks(n_epochs):
        ci, m = clock_index[rows], mask[rows]
        los, rng = line_of_sight(sat_xyz[rows], x[rows])
        los_enu, elev, azim = local_angles(los, lat[rows], lon[rows])
        pr = pr_m[rows] - (np.nan_to_num(correction(lat[rows], lon[rows], h[rows], elev, azim, rows)) if correction is not None else 0.0)
        out["elev_deg"][rows], out["azim_deg"][rows] = elev, azim
        out["dy_m"][rows] = np.where(m, pr - (rng + _clock_term(x[rows], ci)), np.nan)
        out["H"][rows] = np.concatenate([-los_enu, (ci[..., None] == np.arange(n_clocks)).astype(float)], axis=-1)
        out["pr_m"][rows] = np.where(m, pr, np.nan)
    return out
