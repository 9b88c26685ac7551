"""Estimate → detect → exclude, over a batch of epochs: the integrity columns.

Columns added to the epoch table (names as in the papers, units in the names):
``raim_mode``, ``n_used`` (measurements in the RAIM), ``dof`` (k), ``slope_max_m``,
``test_stat`` (WSSE), ``test_stat_source`` (grs, gst_approx, pseudorange, none),
``threshold``, ``lambda_det``, ``hpl_m``, ``hal_m``, ``p_fa``, ``p_md``,
``raim_status``, ``excluded_sv``, ``fde_shift_e_m``/``fde_shift_n_m`` (how far the
position moves when the excluded measurement is dropped), ``hpl_sbas_m`` (paper 004's
K_H·d_major from the per-satellite σ's: an accuracy bound, not a RAIM output).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.wls import Geometry, residuals_from_prefit, wls_geometry, wsse
from tollcli.integrity.fde import exclude
from tollcli.integrity.kalman_hit import hpl_sbas_m
from tollcli.integrity.raim import FAULT, PROBABLE_FALSE_ALARM, STATUSES, RaimParams, detect, status_names

RAIM_COLUMNS = (
    "raim_mode", "n_used", "dof", "slope_max_m", "test_stat", "test_stat_source", "threshold", "lambda_det",
    "hpl_m", "hal_m", "p_fa", "p_md", "raim_status", "excluded_sv", "fde_shift_e_m", "fde_shift_n_m", "hpl_sbas_m",
)  # fmt: skip


def run_raim(meas: Measurements, params: RaimParams, hal_m=None, geometry: Geometry | None = None) -> pd.DataFrame:
    """One row of RAIM results per epoch of ``meas`` (``hal_m``: scalar or per epoch).

    ``geometry``: ``wls_geometry`` of ``meas`` when already computed (it does not depend on the HAL).
    """
    if geometry is None:
        geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
    n_epochs = meas.mask.shape[0]
    if meas.dy_m is not None:
        residual, _ = residuals_from_prefit(meas.H, geometry, meas.dy_m, meas.mask)
    elif meas.residual_m is not None:
        residual = meas.residual_m
    else:
        residual = np.full(meas.mask.shape, np.nan)
    t = wsse(residual, geometry)
    if meas.test_stat_override is not None:
        t = np.where(np.isnan(t), meas.test_stat_override, t)
    detection = detect(geometry, t, params, hal_m=hal_m)
    excluded_sv = np.full(n_epochs, "", dtype=object)
    shift = np.zeros((n_epochs, 3))
    if params.fde:
        exclusion = exclude(meas.H, meas.sigma_m, meas.mask, residual, geometry, detection, params)
        hit = exclusion.excluded_slot >= 0
        excluded_sv[hit] = meas.sv[np.flatnonzero(hit), exclusion.excluded_slot[hit]]
        shift = exclusion.shift_enu_m
    source = meas.test_stat_source if meas.test_stat_source is not None else np.full(n_epochs, "none", dtype=object)
    status = detection.status.copy()
    with np.errstate(invalid="ignore"):  # an alarm at a P_FA above the one asked for is probably false (ETC)
        status[(status == FAULT) & (detection.p_fa > params.p_fa)] = PROBABLE_FALSE_ALARM
    if meas.satellites_reported is not None:  # a receiver that reports no satellites at all (GGA/RMC only): nothing
        status[~meas.satellites_reported & (geometry.n_meas == 0)] = STATUSES.index("unmonitored")  # to monitor, not "too few"
    return pd.DataFrame(
        {
            "raim_mode": pd.array([params.mode] * n_epochs, dtype="string"),
            "n_used": geometry.n_meas.astype(np.int16),
            "dof": detection.dof.astype(np.int16),
            "slope_max_m": detection.slope_max_m,
            "test_stat": detection.test_stat,
            "test_stat_source": pd.array(source, dtype="string"),
            "threshold": detection.threshold,
            "lambda_det": detection.lambda_det,
            "hpl_m": detection.hpl_m,
            "hal_m": detection.hal_m,
            "p_fa": detection.p_fa,
            "p_md": np.full(n_epochs, params.p_md),
            "raim_status": pd.array(status_names(status), dtype="string"),
            "excluded_sv": pd.array(excluded_sv, dtype="string"),
            "fde_shift_e_m": shift[:, 0],
            "fde_shift_n_m": shift[:, 1],
            "hpl_sbas_m": hpl_sbas_m(geometry, meas.sigma_m),
        }
    )
