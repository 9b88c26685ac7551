"""Fault detection and exclusion: drop one measurement when exactly one N−1 subset passes.

For an epoch with ``fault_detected`` and k ≥ 2, each subset without measurement j
is tested with its own geometry (slopes, thresholds, HPL) and its own test
statistic. The subset statistic comes from the full-set residuals by the
leave-one-out identity of least squares (no refit needed, exact for the
linearised model, and usable with receiver-reported GRS residuals):

    t₍ⱼ₎ = t − r_j² / (σ_j² (I − B)_jj)

and so does the change of the solution: Δx₍ⱼ₎ = Δx − A[:, j]·r_j/(I − B)_jj.
The subsets of all flagged epochs are stacked into one batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.gnss.wls import REDUNDANCY_EPS, Geometry, wls_geometry
from tollcli.integrity.raim import EXCLUDED, FAULT, VALID, Detection, RaimParams, detect


@dataclass
class Exclusion:
    excluded_slot: np.ndarray  # (E,) slot index of the excluded measurement, -1 none
    shift_enu_m: np.ndarray  # (E, 3) change of the position when it is excluded (0 otherwise)


def exclude(
    H: np.ndarray,
    sigma_m: np.ndarray,
    mask: np.ndarray,
    residual_m: np.ndarray,
    geometry: Geometry,
    detection: Detection,
    params: RaimParams,
) -> Exclusion:
    """Try single exclusions where a fault was detected; updates ``detection`` in place."""
    n_epochs, n_slots = mask.shape
    out = Exclusion(np.full(n_epochs, -1, dtype=np.int64), np.zeros((n_epochs, 3)))
    flagged = np.flatnonzero((detection.status == FAULT) & (detection.dof >= 2))
    if flagged.size == 0:
        return out
    f_mask = mask[flagged] & (geometry.weight[flagged] > 0)
    red = geometry.redundancy[flagged]
    r = np.nan_to_num(residual_m[flagged])
    w = geometry.weight[flagged]
    checked = f_mask & (red > REDUNDANCY_EPS)
    with np.errstate(divide="ignore", invalid="ignore"):
        drop = np.where(checked, w * r**2 / np.where(checked, red, 1.0), np.nan)
    t_sub = detection.test_stat[flagged][:, None] - drop  # (F, N)

    # one subset per (flagged epoch, slot): stack them as a batch of pseudo-epochs
    eye = np.eye(n_slots, dtype=bool)
    sub_mask = (f_mask[:, None, :] & ~eye[None, :, :]).reshape(-1, n_slots)
    sub_H = np.repeat(H[flagged], n_slots, axis=0)
    sub_sigma = np.repeat(sigma_m[flagged], n_slots, axis=0)
    sub_geom = wls_geometry(sub_H, sub_sigma, sub_mask)
    sub_hal = np.repeat(detection.hal_m[flagged], n_slots)
    sub_det = detect(sub_geom, t_sub.reshape(-1), params, hal_m=sub_hal)
    passes = ((sub_det.status == VALID).reshape(-1, n_slots)) & checked
    single = passes.sum(axis=1) == 1
    if not single.any():
        return out
    rows = np.flatnonzero(single)
    slot = np.argmax(passes[rows], axis=1)
    epochs = flagged[rows]
    pick = rows * n_slots + slot
    out.excluded_slot[epochs] = slot
    A_col = geometry.A[epochs, :3, slot]  # (M, 3)
    out.shift_enu_m[epochs] = -A_col * (r[rows, slot] / red[rows, slot])[:, None]
    for name in ("dof", "slope_max_m", "test_stat", "threshold", "lambda_det", "hpl_m", "p_fa"):
        getattr(detection, name)[epochs] = getattr(sub_det, name)[pick]
    detection.status[epochs] = EXCLUDED
    return out
