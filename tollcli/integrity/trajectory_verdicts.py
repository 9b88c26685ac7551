"""The integrity columns of epochs the trajectory estimator placed (``--positioning smoothed|filtered``).

The same columns as :func:`tollcli.integrity.run.run_raim`'s, from :mod:`tollcli.integrity.trajectory`'s bound and
fault test: ``fault_detected`` where the test statistic exceeds χ²_dof's (1 − P_FA) quantile (evidence that a pass
took in a fault: the two passes disagree beyond any correlation of their errors, or the kept innovations are too
large), or where a pass of the estimator lost the vehicle (most of an epoch's measurements rejected: its motion
model was wrong there), else ``unavailable`` where HPL > HAL, else ``valid``; ``insufficient`` where the estimator gave no bound.
The position vouched for is the trajectory's own (no shift). ``integrity_source`` and ``raim_mode`` name the
positioning; ``excluded_sv`` counts the measurements the robust loss set aside (``set_aside:N``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements
from tollcli.integrity.design import classic_threshold
from tollcli.integrity.raim import FAULT, INSUFFICIENT, UNAVAILABLE, VALID, RaimParams, status_names


def trajectory_raim(meas: Measurements, params: RaimParams, hal_m=None) -> pd.DataFrame:
    """One row of integrity results per epoch of ``meas`` (its ``trajectory_*`` arrays set)."""
    n = meas.mask.shape[0]
    hpl = np.asarray(meas.trajectory_hpl_m, float)
    t = np.asarray(meas.trajectory_test_stat, float)
    dof = np.asarray(meas.trajectory_dof, np.int64)
    hal = np.broadcast_to(np.asarray(params.hal_m if hal_m is None else hal_m, float), (n,)).astype(float)
    threshold = classic_threshold(params.p_fa, dof)
    status = np.full(n, VALID)
    status[hpl > hal] = UNAVAILABLE
    with np.errstate(invalid="ignore"):
        status[t > threshold] = FAULT
    if meas.trajectory_lost is not None:
        status[np.asarray(meas.trajectory_lost, bool)] = FAULT
    status[~np.isfinite(hpl)] = INSUFFICIENT
    aside = np.asarray(meas.trajectory_set_aside, np.int64)
    nan = np.full(n, np.nan)
    name = pd.array(np.asarray(meas.trajectory_source, dtype=object), dtype="string")
    none = pd.array(np.full(n, "", object), dtype="string")
    return pd.DataFrame(
        {
            "raim_mode": name,
            "n_used": meas.mask.sum(axis=1).astype(np.int16),
            "dof": dof.astype(np.int16),
            "slope_max_m": nan,
            "test_stat": t,
            "test_stat_source": name,
            "threshold": threshold,
            "lambda_det": nan,
            "hpl_m": hpl,
            "hal_m": hal,
            "p_fa": np.full(n, params.p_fa),
            "p_md": np.full(n, params.p_md),
            "raim_status": pd.array(status_names(status), dtype="string"),
            "integrity_source": name,
            "residual_status": none,
            "gbs_status": none,
            "gst_status": none,
            "hpl_gbs_m": nan,
            "hpl_gst_m": nan,
            "hpl_model_m": nan,
            "gst_rms_note": none,
            "excluded_sv": pd.array(np.where(aside > 0, np.char.add("set_aside:", aside.astype(str)), "").astype(object),
                                    dtype="string"),  # fmt: skip
            "fde_shift_e_m": np.zeros(n),
            "fde_shift_n_m": np.zeros(n),
            "wls_shift_e_m": np.zeros(n),
            "wls_shift_n_m": np.zeros(n),
            "hpl_sbas_m": nan,
            "separation_ratio": nan,
        }
    )
