"""The simulated receiver's logs: NMEA 0183 (4.10), the GSDC derived CSV and (with odometry) libRSF text.

NMEA per epoch: RMC, VTG, GGA, GSA per constellation (with system id), GSV per
constellation (with signal id), GST, GRS per constellation (residuals in GSA
order) — what a multi-GNSS receiver with RAIM outputs. Without a fix, GGA has
quality 0, RMC status V, and GSA/GST/GRS are not written. The GSDC derived CSV
has one row per received satellite: ECEF at transmission, the pseudorange, σ as
``rawPrUncM``, no satellite clock, ionosphere or troposphere terms (the simulated
errors are the residuals after those corrections). The libRSF text is the smartLoc layout
(:mod:`tollcli.readers.librsf`): ``pseudorange3`` lines (the same pseudoranges, σ² as the variance, Galileo numbered
300 + PRN) and ``odom3`` lines (the odometer's speed, the gyro's yaw rate and their variances), times in seconds
from the start; the truth as ``point3`` lines (ECEF).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator

import numpy as np
import pandas as pd

from tollcli.readers.gps_time import LEAP_SECONDS
from tollcli.readers.nmea import compose

TALKER = {"GPS": "GP", "Galileo": "GA"}
SYSTEM_ID = {"GPS": 1, "Galileo": 3}
SIGNAL_ID = {"GPS": 1, "Galileo": 7}  # L1 C/A, E1 B/C
ANDROID_TYPE = {"GPS": 1, "Galileo": 6}
SIGNAL_TYPE = {"GPS": "GPS_L1", "Galileo": "GAL_E1"}


def nmea_lines(epochs: pd.DataFrame, satellites: pd.DataFrame) -> Iterator[str]:
    """NMEA sentences for a chunk of simulated epochs (a loop per epoch: output formatting, not a hot path)."""
    by_epoch = {e: g for e, g in satellites.groupby("epoch", sort=True)}
    empty = satellites.iloc[:0]
    for row in epochs.itertuples(index=False):
        ts = pd.Timestamp(row.time_utc)
        tod = ts.hour * 3600 + ts.minute * 60 + ts.second + ts.microsecond / 1e6
        date = ts.date()
        sats = by_epoch.get(row.epoch, empty)
        if row.fix:
            yield compose.rmc(tod, row.lat_deg, row.lon_deg, row.speed_mps, row.course_deg, date)
            yield compose.vtg(row.speed_mps, row.course_deg)
            yield compose.gga(tod, row.lat_deg, row.lon_deg, 1, int(row.n_used), row.hdop, row.height_m, 0.0)
        else:
            yield compose.with_checksum(f"GNRMC,{compose.hhmmss(tod)},V,,,,,,,{date:%d%m%y},,,N")
            yield compose.with_checksum(f"GNGGA,{compose.hhmmss(tod)},,,,,0,{int(row.n_used):02d},,,M,,M,,")
        groups = list(sats.groupby("constellation", sort=True))
        if row.fix:
            for name, g in groups:
                yield compose.gsa(g["svid"].tolist(), row.pdop, row.hdop, row.vdop, 3, system_id=SYSTEM_ID[name])
        for name, g in groups:
            quads = list(zip(g["svid"].tolist(), g["elev_deg"].round(1).tolist(), g["azim_deg"].round(1).tolist(),
                             g["cn0_dbhz"].tolist()))  # fmt: skip
            yield from compose.gsv(quads, TALKER[name], signal_id=SIGNAL_ID[name])
        if row.fix:
            yield compose.gst(tod, row.rms_residual_m, row.sigma_major_m, row.sigma_minor_m, row.ellipse_orient_deg,
                              row.sigma_lat_m, row.sigma_lon_m, 2.0 * row.sigma_lat_m)  # fmt: skip
            for name, g in groups:
                yield compose.grs(tod, g["residual_m"].tolist(), system_id=SYSTEM_ID[name])


def gps_millis(time_utc: pd.Series) -> np.ndarray:
    """UTC times → GPS milliseconds since 1980-01-06 (leap seconds added)."""
    utc = time_utc.dt.tz_convert(None).to_numpy().astype("datetime64[ms]")
    leap = np.zeros(utc.shape, dtype=np.int64)
    for date, seconds in LEAP_SECONDS:
        leap = np.where(utc >= np.datetime64(date, "ms"), seconds, leap)
    return (utc - np.datetime64("1980-01-06T00:00:00", "ms")).astype(np.int64) + 1000 * leap


def gsdc_rows(epochs: pd.DataFrame, satellites: pd.DataFrame) -> pd.DataFrame:
    """The GSDC derived CSV rows of a chunk."""
    millis = pd.Series(gps_millis(epochs["time_utc"]), index=epochs["epoch"].to_numpy())
    const = satellites["constellation"]
    zero = np.zeros(len(satellites))
    return pd.DataFrame({
        "collectionName": "tollcli-simulate", "phoneName": "simulated",
        "millisSinceGpsEpoch": millis.loc[satellites["epoch"].to_numpy()].to_numpy(),
        "constellationType": const.map(ANDROID_TYPE).to_numpy(), "svid": satellites["svid"].to_numpy(),
        "signalType": const.map(SIGNAL_TYPE).to_numpy(),
        "receivedSvTimeInGpsNanos": zero.astype(np.int64),
        "xSatPosM": satellites["x_sv_m"].round(3).to_numpy(), "ySatPosM": satellites["y_sv_m"].round(3).to_numpy(),
        "zSatPosM": satellites["z_sv_m"].round(3).to_numpy(),
        "xSatVelMps": zero, "ySatVelMps": zero, "zSatVelMps": zero,
        "satClkBiasM": zero, "satClkDriftMps": zero,
        "rawPrM": satellites["pr_m"].round(4).to_numpy(), "rawPrUncM": satellites["sigma_m"].round(4).to_numpy(),
        "isrbM": zero, "ionoDelayM": zero, "tropoDelayM": zero,
    })  # fmt: skip


def truth_rows(epochs: pd.DataFrame) -> pd.DataFrame:
    """The truth trajectory CSV rows (what ``tollcli audit --truth`` reads)."""
    return pd.DataFrame({
        "time_utc": epochs["time_utc"].dt.strftime("%Y-%m-%dT%H:%M:%S.%f").str[:-3] + "Z",
        "lat_deg": epochs["true_lat_deg"].round(9), "lon_deg": epochs["true_lon_deg"].round(9),
        "height_m": epochs["true_height_m"].round(3), "speed_mps": epochs["true_speed_mps"].round(4),
        "heading_deg": epochs["true_heading_deg"].round(4), "faulty": epochs["faulty"].astype(int),
        "n_visible": epochs["n_used"].astype(int),
    })  # fmt: skip


def start_date(epochs: pd.DataFrame) -> dt.date:
    return pd.Timestamp(epochs["time_utc"].iloc[0]).date()


#: libRSF system codes (smartLoc: 1 GPS, 3 Galileo) and Galileo's satellite numbers
LIBRSF_SYSTEM = {"GPS": 1, "Galileo": 3}
LIBRSF_GALILEO_ID0 = 300


def librsf_lines(epochs: pd.DataFrame, satellites: pd.DataFrame, config) -> Iterator[str]:
    """A chunk's ``odom3`` and ``pseudorange3`` lines (without line ends), epoch by epoch (odometry first, as smartLoc writes them)."""
    t_of = pd.Series(epochs["t_s"].to_numpy(float), index=epochs["epoch"].to_numpy())
    v_var, w_var = config.odo_speed_sigma_mps**2, config.gyro_sigma_radps**2
    odom = {int(e): f"odom3 {t:.3f} {v:.6f} 0 0 0 0 {w:.9f} {v_var:g} {v_var:g} {v_var:g} {w_var:g} {w_var:g} {w_var:g}"
            for e, t, v, w in zip(epochs["epoch"], epochs["t_s"], epochs["odo_speed_mps"], epochs["odo_yaw_rate_radps"])}  # fmt: skip
    const = satellites["constellation"].to_numpy(object)
    sat_id = np.where(const == "Galileo", LIBRSF_GALILEO_ID0, 0) + satellites["svid"].to_numpy(np.int64)
    system = np.where(const == "Galileo", LIBRSF_SYSTEM["Galileo"], LIBRSF_SYSTEM["GPS"])
    rows: dict[int, list[str]] = {}
    for e, pr, sg, x, y, z, sid, sy, el, c in zip(satellites["epoch"].to_numpy(), satellites["pr_m"].to_numpy(),
                                                   satellites["sigma_m"].to_numpy(), satellites["x_sv_m"].to_numpy(),
                                                   satellites["y_sv_m"].to_numpy(), satellites["z_sv_m"].to_numpy(), sat_id,
                                                   system, satellites["elev_deg"].to_numpy(), satellites["cn0_dbhz"].to_numpy()):  # fmt: skip
        rows.setdefault(int(e), []).append(f"pseudorange3 {t_of[e]:.3f} {pr:.4f} {sg * sg:.4f} {x:.4f} {y:.4f} {z:.4f} {sid} {sy} {el:.4f} {c:.2f}")
    for e in epochs["epoch"].to_numpy():
        yield odom[int(e)]
        yield from rows.get(int(e), [])


def librsf_truth_lines(epochs: pd.DataFrame) -> Iterator[str]:
    """The chunk's true positions as libRSF ``point3`` lines (ECEF, m)."""
    from tollcli.geodesy import geodetic2ecef

    x, y, z = geodetic2ecef(epochs["true_lat_deg"].to_numpy(float), epochs["true_lon_deg"].to_numpy(float),
                            epochs["true_height_m"].to_numpy(float))  # fmt: skip
    for t, a, b, c in zip(epochs["t_s"].to_numpy(float), np.atleast_1d(x), np.atleast_1d(y), np.atleast_1d(z)):
        yield f"point3 {t:.3f} {a:.4f} {b:.4f} {c:.4f} 0 0 0 0 0 0 0 0 0"
