"""One schema for the batch's epoch dataset, whatever the input kind (NMEA, GSDC, Android raw, RINEX, u-blox).

DuckDB, Spark and pandas read a Hive-partitioned Parquet folder as one table only when every file has the same
columns and types; with each reader's own columns they silently keep the first file's. Every epoch table the
batch writes is conformed to :data:`EPOCH_COLUMNS`: a column the input kind does not have is null (and says so:
unknown, not zero), types are the ones listed. ``height_m`` is the ellipsoidal height for every kind: for NMEA
it is GGA's altitude above the geoid (``alt_m``) plus its geoid separation, where both are given.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: column → Arrow type name, in the dataset's column order (units in the names, as everywhere)
EPOCH_COLUMNS: dict[str, str] = {
    # when and where
    "epoch": "int64", "line": "int64", "time_utc": "timestamp[ms, tz=UTC]", "time_gps": "timestamp[ms]",
    "gps_millis": "int64", "tod_s": "float64",
    "lat_deg": "float64", "lon_deg": "float64", "height_m": "float64", "alt_m": "float64", "geoid_sep_m": "float64",
    "speed_mps": "float64", "course_deg": "float64", "vel_up_mps": "float64", "speed_doppler_sigma_mps": "float64",
    "clock_bias_m": "float64", "clock_drift_mps": "float64",
    # what the receiver said about its fix
    "fix_quality": "int8", "fix_mode": "int8", "fix_valid": "bool", "mode_indicator": "string",
    "n_measurements": "int16", "n_doppler": "int16", "n_used_receiver": "int16", "n_in_view": "int16",
    "hdop": "float64", "pdop": "float64", "vdop": "float64", "rms_residual_m": "float64",
    "sigma_major_m": "float64", "sigma_minor_m": "float64", "ellipse_orient_deg": "float64",
    "sigma_lat_m": "float64", "sigma_lon_m": "float64", "sigma_alt_m": "float64",
    "gbs_err_lat_m": "float64", "gbs_err_lon_m": "float64", "gbs_err_alt_m": "float64", "gbs_failed_svid": "int16",
    "gbs_p_md": "float64", "gbs_bias_m": "float64", "gbs_bias_sd_m": "float64",
    "receiver_lat_deg": "float64", "receiver_lon_deg": "float64", "receiver_height_m": "float64",
    "receiver_h_acc_m": "float64", "receiver_speed_mps": "float64",
    "pos_disagreement_m": "float64", "date_disagreement_days": "float64", "date_jump_days": "float64",
    # the integrity verdict
    "environment": "string", "variance_factor": "float64", "raim_mode": "string", "n_used": "int16", "dof": "int16", "slope_max_m": "float64", "test_stat": "float64",
    "test_stat_source": "string", "threshold": "float64", "lambda_det": "float64", "hpl_m": "float64",
    "hal_m": "float64", "p_fa": "float64", "p_md": "float64", "raim_status": "string", "integrity_source": "string",
    "residual_status": "string", "gbs_status": "string", "gst_status": "string", "hpl_gbs_m": "float64",
    "hpl_gst_m": "float64", "hpl_model_m": "float64", "hpl_sbas_m": "float64", "separation_ratio": "float64", "gst_rms_note": "string", "excluded_sv": "string",
    "fde_shift_e_m": "float64", "fde_shift_n_m": "float64", "wls_shift_e_m": "float64", "wls_shift_n_m": "float64", "raim_lat_deg": "float64", "raim_lon_deg": "float64",
}  # fmt: skip


def epoch_schema():
    """The Arrow schema of :data:`EPOCH_COLUMNS`."""
    import pyarrow as pa

    def arrow(name: str):
        if name.startswith("timestamp"):
            return pa.timestamp("ms", tz="UTC" if "UTC" in name else None)
        return {"string": pa.string(), "bool": pa.bool_()}.get(name) or pa.from_numpy_dtype(np.dtype(name))

    return pa.schema([(c, arrow(t)) for c, t in EPOCH_COLUMNS.items()])


def unknown_columns(table: pd.DataFrame) -> list[str]:
    """Columns of an epoch table the schema does not have (a reader that grew one: the schema must grow too)."""
    return [c for c in table.columns if c not in EPOCH_COLUMNS]


def conform_epochs(table: pd.DataFrame) -> pd.DataFrame:
    """The epoch table with exactly the schema's columns, in its order (missing ones null)."""
    out = table.copy(deep=False)
    if "height_m" not in out and {"alt_m", "geoid_sep_m"} <= set(out.columns):
        out["height_m"] = out["alt_m"].to_numpy(float) + out["geoid_sep_m"].to_numpy(float)
    missing = [c for c in EPOCH_COLUMNS if c not in out]
    if missing:
        out = pd.concat([out, pd.DataFrame({c: pd.Series([None] * len(out), dtype=object, index=out.index) for c in missing})], axis=1)
    return out[list(EPOCH_COLUMNS)]
