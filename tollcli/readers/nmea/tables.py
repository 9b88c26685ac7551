"""The epoch and satellite table layouts (column names carry their units).

Epoch table, one row per fix time:

=====================  =============================================================
``epoch``              running index of the epoch in the log (joins the two tables)
``time_utc``           UTC date-time, ms resolution (NaT when the log has no date)
``tod_s``              time of day, seconds after midnight UTC
``line``               line number of the epoch's first sentence
``lat_deg``/``lon_deg``  WGS-84 position, degrees (GGA > GNS > RMC > GLL)
``alt_m``              altitude above mean sea level, m (GGA/GNS)
``geoid_sep_m``        geoid separation, m
``fix_quality``        GGA quality indicator (0 none, 1 GNSS, 2 DGNSS, 4/5 RTK, 6 DR; -1 absent)
``fix_mode``           GSA mode (1 no fix, 2 2-D, 3 3-D; -1 absent)
``fix_valid``          the receiver claims a GNSS fix (GGA quality 1–5, else RMC/GLL 'A', else GSA ≥ 2)
``mode_indicator``     RMC/GLL/GNS mode letter (A autonomous, D differential, E estimated, N none…)
``n_used``             satellites used in the fix (GSA count, else GGA/GNS)
``n_in_view``          satellites reported in GSV (-1: no GSV in the epoch, unknown; 0: a GSV listing none)
``hdop``/``pdop``/``vdop``  dilutions of precision (GSA; HDOP falls back to GGA)
``speed_mps``          speed over ground, m/s (RMC, else VTG)
``course_deg``         course over ground, degrees from true north
``rms_residual_m``     GST RMS of the pseudorange residuals, m
``sigma_major_m``/``sigma_minor_m``/``ellipse_orient_deg``  GST error ellipse (1σ, m; degrees from north)
``sigma_lat_m``/``sigma_lon_m``/``sigma_alt_m``  GST 1σ position errors, m
``gbs_err_*_m``        GBS expected position errors, m
``gbs_failed_svid``    GBS most likely failed satellite (-1 none)
``gbs_p_md``           GBS probability of missed detection of that satellite
``gbs_bias_m``/``gbs_bias_sd_m``  GBS estimated bias on it and its standard deviation, m
``pos_disagreement_m``  largest distance between the positions two sentences (GGA, GNS, RMC, GLL) give
                       for the same epoch, m (NaN when only one gave a position)
``date_disagreement_days``  ZDA date minus RMC date when both are in the epoch and differ (NaN otherwise)
``date_jump_days``     the date the epoch's RMC/ZDA gave minus the date its continuous trip carries, where they
                       differ (a date jump or week-number rollover; the epoch keeps the trip's date; NaN otherwise)
=====================  =============================================================

Satellite table, one row per satellite and epoch (the union of GSV "in view" and
GSA "used"): ``epoch``, ``time_utc``, ``constellation``, ``svid`` (system-native
number), ``prn`` (as numbered in the log, -1 if only in GSA), ``signal_id``
(NMEA 4.10 GSV signal id of the reported C/N0, -1 if none), ``elev_deg``,
``azim_deg``, ``cn0_dbhz``, ``used``, ``residual_m`` (GRS range residual, m).
Where a satellite is reported on several signals, the row carries the lowest
signal id (the primary signal, e.g. L1 C/A).
"""

from __future__ import annotations

import numpy as np

from tollcli.io.columns import UTC_MS, Coded, Columns
from tollcli.readers.nmea.assembler import FLOAT_COLUMNS
from tollcli.readers.nmea.satellite_ids import CONSTELLATIONS

EPOCH_COLUMNS = (
    "epoch", "time_utc", "tod_s", "line", "lat_deg", "lon_deg", "alt_m", "geoid_sep_m",
    "fix_quality", "fix_mode", "fix_valid", "mode_indicator", "n_used", "n_in_view",
    "hdop", "pdop", "vdop", "speed_mps", "course_deg",
    "rms_residual_m", "sigma_major_m", "sigma_minor_m", "ellipse_orient_deg",
    "sigma_lat_m", "sigma_lon_m", "sigma_alt_m",
    "gbs_err_lat_m", "gbs_err_lon_m", "gbs_err_alt_m", "gbs_failed_svid", "gbs_p_md",
    "gbs_bias_m", "gbs_bias_sd_m", "pos_disagreement_m", "date_disagreement_days",
    "date_jump_days",
)  # fmt: skip

SATELLITE_COLUMNS = (
    "epoch", "time_utc", "constellation", "svid", "prn", "signal_id",
    "elev_deg", "azim_deg", "cn0_dbhz", "used", "residual_m",
)  # fmt: skip

_EPOCH_DTYPES = {
    "epoch": np.int64, "tod_s": np.float64, "line": np.int64, "fix_quality": np.int8,
    "fix_mode": np.int8, "fix_valid": bool, "mode_indicator": object, "n_used": np.int16,
    "n_in_view": np.int16, "gbs_failed_svid": np.int16,
    **{k: np.float64 for k in FLOAT_COLUMNS}, "date_jump_days": np.float64,
}  # fmt: skip
_SAT_SOURCES = {
    "constellation": ("sat_constellation", np.int8), "svid": ("sat_svid", np.int16),
    "prn": ("sat_prn", np.int16), "signal_id": ("sat_signal_id", np.int8),
    "elev_deg": ("sat_elev_deg", np.float64), "azim_deg": ("sat_azim_deg", np.float64),
    "cn0_dbhz": ("sat_cn0_dbhz", np.float64), "used": ("sat_used", bool),
    "residual_m": ("sat_residual_m", np.float64),
}  # fmt: skip


def epoch_columns(arrays: dict[str, np.ndarray] | None, time_utc: np.ndarray | None = None) -> Columns:
    """The epoch table from the assembler's arrays (an empty table for ``None``), as :class:`Columns`."""
    if arrays is None:
        arrays = {k: np.empty(0, dtype=t) for k, t in _EPOCH_DTYPES.items()}
        arrays["epoch"] = np.empty(0, dtype=np.int64)
        time_utc = np.empty(0, dtype=UTC_MS)
    data = {}
    for name in EPOCH_COLUMNS:
        if name == "time_utc":
            data[name] = np.asarray(time_utc).astype(UTC_MS, copy=False)
        else:
            data[name] = np.asarray(arrays[name], dtype=_EPOCH_DTYPES[name])
    return Columns(data)


def satellite_columns(arrays: dict[str, np.ndarray] | None, time_utc: np.ndarray | None) -> Columns:
    """The satellite table as :class:`Columns`; ``time_utc`` is the epoch table's, looked up by epoch."""
    if arrays is None:
        data = {"epoch": np.empty(0, np.int64), "time_utc": np.empty(0, UTC_MS)}
        for name, (_, dtype) in _SAT_SOURCES.items():
            data[name] = np.empty(0, dtype=object if name == "constellation" else dtype)
        return Columns(data)
    sat_epoch = arrays["sat_epoch"]
    first = arrays["epoch"][0] if arrays["epoch"].size else 0
    data = {"epoch": sat_epoch, "time_utc": np.asarray(time_utc).astype(UTC_MS, copy=False)[sat_epoch - first]}
    for name, (key, dtype) in _SAT_SOURCES.items():
        values = np.asarray(arrays[key], dtype=dtype)
        data[name] = Coded(values, CONSTELLATIONS) if name == "constellation" else values
    return Columns(data)


def epoch_frame(arrays: dict[str, np.ndarray] | None, time_utc: np.ndarray | None = None):
    """The epoch table as a pandas DataFrame (:func:`epoch_columns` converted)."""
    return epoch_columns(arrays, time_utc).to_pandas()


def satellite_frame(arrays: dict[str, np.ndarray] | None, time_utc: np.ndarray | None):
    """The satellite table as a pandas DataFrame (:func:`satellite_columns` converted)."""
    return satellite_columns(arrays, time_utc).to_pandas()
