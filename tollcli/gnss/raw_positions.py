"""Raw measurements (Android ``Raw``, GSDC 2022 ``device_gnss``, u-blox ``RXM-RAWX``) → WLS positions,
Doppler velocities and RAIM measurements.

The input is one row per satellite-signal and epoch (:func:`tollcli.gnss.android_raw.raw_pseudoranges`,
:func:`tollcli.gnss.ubx_measurements.rawx_measurements`) with ``epoch_key``, ``t_rx_gps_s``, ``sv``,
``constellation``, ``signal``, ``carrier_hz``, ``pr_m``, ``pr_sigma_m``, ``prr_mps``, ``prr_sigma_mps``,
``cn0_dbhz``, ``pr_valid``. Satellites come either from broadcast ephemerides
(:func:`with_broadcast_satellites`: GPS, Galileo, BeiDou and GLONASS, Klobuchar + Saastamoinen modelled here, one
receiver clock per constellation and signal, since inter-signal biases are unknown) or from the
file's own columns (:func:`with_device_gnss_satellites`: Google's satellite states and delays with the
inter-signal bias removed, so one clock serves all).

Each epoch's position is the iterated Sagnac-corrected WLS of :mod:`tollcli.gnss.pseudorange_wls`;
its velocity the Doppler WLS of :mod:`tollcli.gnss.doppler_velocity` at that position. The epoch
table carries ``speed_mps``/``course_deg`` from Doppler and ``speed_doppler_sigma_mps`` (its 1σ), which
the speed check uses instead of a configured SDOP.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m
from tollcli.gnss.doppler_velocity import doppler_velocity
from tollcli.gnss.measurements import Measurements, pad, slots
from tollcli.gnss.orbits import WEEK_S
from tollcli.gnss.pseudorange_wls import (
    C_MPS,
    final_geometry,
    line_of_sight,
    solvable,
    solve_positions,
)
from tollcli.gnss.satellite_states import NoOrbitForRows, satellite_states
from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.readers.gps_time import gps_millis_to_utc

L1_HZ = 1_575_420_000.0
SAT_COLUMNS = ("sat_x_m", "sat_y_m", "sat_z_m", "sat_vx_mps", "sat_vy_mps", "sat_vz_mps", "sat_clock_m", "sat_drift_mps")
#: the constellations whose broadcast orbits are computed here (:mod:`tollcli.gnss.satellite_states`)
BROADCAST_CONSTELLATIONS = ("GPS", "Galileo", "BeiDou", "GLONASS")
#: BeiDou signals usable with the D1 message's clock (B3I's), and the group delay each subtracts (TGD1: B1I, TGD2:
#: B2I); B1C and B2a are left out: their group delays are broadcast in B-CNAV1/2, not decoded here
BEIDOU_GROUP_DELAY = {"B3I": None, "B1I": "tgd1_s", "B2I": "tgd2_s"}
#: a rate σ where the input gives none (m/s; a phone's typical PseudorangeRateUncertainty)
DEFAULT_PRR_SIGMA_MPS = 0.2


def with_broadcast_satellites(m: pd.DataFrame, ephemerides: pd.DataFrame) -> pd.DataFrame:
    """``m`` with the satellite columns from broadcast ephemerides (NaN where none is known); records without a
    receiver time (clock fields missing or damaged) are left out: they belong to no epoch."""
    m = m[np.isfinite(m["t_rx_gps_s"].to_numpy(float))].reset_index(drop=True)
    constellation, signal = m["constellation"].to_numpy(object), m["signal"].to_numpy(object)
    use = m["pr_valid"].to_numpy(bool) & np.isin(constellation, BROADCAST_CONSTELLATIONS)
    beidou = constellation == "BeiDou"
    use &= ~beidou | np.isin(signal, tuple(BEIDOU_GROUP_DELAY))  # B1C, B2a: their delays are not in D1
    states = satellite_states(ephemerides, m["sv"].to_numpy(str), m["t_rx_gps_s"].to_numpy(float),
                              np.where(use, m["pr_m"].to_numpy(float), 2.2e7))  # fmt: skip
    for name, column in BEIDOU_GROUP_DELAY.items():  # the broadcast clock is B3I's
        if column is not None:
            rows = beidou & (signal == name)
            states["clock_s"][rows] -= np.nan_to_num(states.get(column, np.zeros(len(m)))[rows])
    have = use & states["have"]
    for k, name in enumerate(SAT_COLUMNS[:3]):
        m[name] = np.where(have, states["pos_m"][:, k], np.nan)
    for k, name in enumerate(SAT_COLUMNS[3:6]):
        m[name] = np.where(have, states["vel_mps"][:, k], np.nan)
    m["sat_clock_m"] = np.where(have, states["clock_s"] * C_MPS, np.nan)
    m["sat_drift_mps"] = np.where(have, states["drift_sps"] * C_MPS, np.nan)
    m["modelled_delay_m"] = np.nan  # ionosphere and troposphere modelled in the WLS
    m["clock_group"] = m["constellation"].astype(str) + " " + m["signal"].astype(str)
    return m


def with_device_gnss_satellites(m: pd.DataFrame, device: pd.DataFrame) -> pd.DataFrame:
    """``m`` with the satellite columns of a GSDC 2022/2023 ``device_gnss.csv`` (same rows)."""
    m = m.copy()
    source = ("SvPositionXEcefMeters", "SvPositionYEcefMeters", "SvPositionZEcefMeters", "SvVelocityXEcefMetersPerSecond",
              "SvVelocityYEcefMetersPerSecond", "SvVelocityZEcefMetersPerSecond", "SvClockBiasMeters",
              "SvClockDriftMetersPerSecond")  # fmt: skip
    for name, col in zip(SAT_COLUMNS, source):
        m[name] = pd.to_numeric(device[col], errors="coerce").to_numpy(float) if col in device else np.nan
    delays = [pd.to_numeric(device[c], errors="coerce").to_numpy(float) if c in device else np.zeros(len(device))
              for c in ("IsrbMeters", "IonosphericDelayMeters", "TroposphericDelayMeters")]  # fmt: skip
    m["modelled_delay_m"] = delays[0] + delays[1] + delays[2]
    m["clock_group"] = "all"  # the inter-signal biases are removed: one receiver clock
    return m


def raw_epochs(m: pd.DataFrame, sigma_model: str = "nominal", sigma_m: float = 5.0, nominal: NominalModel | None = None,
               iono_coeffs=None, orbits_required: bool = True) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """WLS position and Doppler velocity per epoch (an epoch table) and the RAIM measurements there. Measurements none
    of which has an orbit raise :class:`~tollcli.gnss.satellite_states.NoOrbitForRows`, or (``orbits_required``
    False) give epochs without positions."""
    timed = np.isfinite(m["t_rx_gps_s"].to_numpy(float))
    if not timed.all():  # a record whose clock fields are missing or damaged has no time: it belongs to no epoch
        m = m[timed].reset_index(drop=True)
    keys = m["epoch_key"].to_numpy()
    epoch_keys, first = np.unique(keys, return_index=True)
    n_epochs = epoch_keys.size
    if n_epochs == 0:
        raise DataError("no measurement epochs")
    epoch_t = m["t_rx_gps_s"].to_numpy(float)[first]
    sat = m[list(SAT_COLUMNS[:3])].to_numpy(float)
    usable = m["pr_valid"].to_numpy(bool) & np.isfinite(sat).all(axis=1) & np.isfinite(m["sat_clock_m"].to_numpy(float))
    if not usable.any() and orbits_required:
        raise NoOrbitForRows("no measurement has both a whole pseudorange and a satellite orbit "
                             "(a navigation file for the day, --nav, gives the orbits)")  # fmt: skip
    d = m[usable]
    row = np.searchsorted(epoch_keys, d["epoch_key"].to_numpy())
    order = np.argsort(row, kind="stable")
    d, row = d.iloc[order], row[order]
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)

    def padded(name: str, fill=np.nan) -> np.ndarray:
        return pad(d[name].to_numpy(), row, slot, shape, fill)

    mask = pad(np.ones(len(d), bool), row, slot, shape, False)
    sat_xyz = np.stack([padded(c, 0.0).astype(float) for c in SAT_COLUMNS[:3]], -1)
    sat_vel = np.stack([padded(c).astype(float) for c in SAT_COLUMNS[3:6]], -1)
    delay = np.nan_to_num(d["modelled_delay_m"].to_numpy(float))
    pr = pad(d["pr_m"].to_numpy(float) + d["sat_clock_m"].to_numpy(float) - delay, row, slot, shape, 0.0)
    pr_sigma = padded("pr_sigma_m").astype(float)
    cn0 = padded("cn0_dbhz").astype(float)
    constellation = pad(d["constellation"].to_numpy(object), row, slot, shape, "")
    labels = pad((d["sv"].astype(str) + " " + d["signal"].astype(str)).to_numpy(object), row, slot, shape, "")
    group_codes, _ = pd.factorize(d["clock_group"].to_numpy(object))
    clock_index = pad(group_codes.astype(np.int64), row, slot, shape, 0)
    iono_scale = pad((L1_HZ / d["carrier_hz"].to_numpy(float)) ** 2, row, slot, shape, 1.0)
    modelled = np.isfinite(d["modelled_delay_m"].to_numpy(float)).all()
    tow = np.mod(epoch_t, WEEK_S)[:, None]

    def correction(lat, lon, h, elev, azim, rows):
        delay = saastamoinen_delay_m(lat[:, None], h[:, None], elev)
        if iono_coeffs is not None and len(iono_coeffs) == 8:
            delay = delay + iono_scale[rows] * klobuchar_delay_m(lat[:, None], lon[:, None], elev, azim, tow[rows],
                                                                 iono_coeffs[:4], iono_coeffs[4:])  # fmt: skip
        return delay

    corr = None if modelled else correction
    sigma_iter = np.where(mask, np.where(np.isfinite(pr_sigma) & (pr_sigma > 0), pr_sigma, sigma_m), np.nan)
    x = solve_positions(sat_xyz, pr, mask, sigma_iter, corr, clock_index)
    g = final_geometry(sat_xyz, pr, mask, x, corr, clock_index)
    sigma = np.where(mask, sigma_for(sigma_model, elev_deg=g["elev_deg"], cn0_dbhz=cn0, constellation=constellation,
                                     lat_deg=g["lat_deg"][:, None], lon_deg=g["lon_deg"][:, None], sigma_input_m=pr_sigma,
                                     sigma_const_m=sigma_m, nominal=nominal), np.nan)  # fmt: skip
    los_ecef, _ = line_of_sight(sat_xyz, x)
    prr_sigma = padded("prr_sigma_mps").astype(float)
    vel = doppler_velocity(-g["H"][..., :3], los_ecef, sat_vel, padded("sat_drift_mps").astype(float),
                           padded("prr_mps").astype(float),
                           np.where(np.isfinite(prr_sigma) & (prr_sigma > 0), prr_sigma, DEFAULT_PRR_SIGMA_MPS),
                           mask & (g["elev_deg"] > 0))  # fmt: skip
    ok = solvable(mask, clock_index) & np.isfinite(g["lat_deg"])
    millis = np.round(epoch_t * 1000).astype(np.int64)
    epochs = pd.DataFrame({
        "epoch": np.arange(n_epochs, dtype=np.int64),
        "time_utc": pd.DatetimeIndex(gps_millis_to_utc(millis)).tz_localize("UTC"),
        "gps_millis": millis,
        "lat_deg": np.where(ok, g["lat_deg"], np.nan),
        "lon_deg": np.where(ok, g["lon_deg"], np.nan),
        "height_m": np.where(ok, g["height_m"], np.nan),
        "clock_bias_m": np.where(ok, x[:, 3], np.nan),
        "n_measurements": mask.sum(axis=1).astype(np.int16),
        "speed_mps": vel["speed_mps"],
        "course_deg": vel["course_deg"],
        "speed_doppler_sigma_mps": vel["speed_sigma_mps"],
        "vel_up_mps": vel["vel_enu_mps"][:, 2],
        "clock_drift_mps": vel["clock_drift_mps"],
        "n_doppler": vel["n_doppler"],
    })  # fmt: skip
    meas = Measurements(g["H"], sigma, mask, labels, dy_m=g["dy_m"], cn0_dbhz=cn0,
                        test_stat_source=np.full(n_epochs, "pseudorange", dtype=object), sat_ecef_m=sat_xyz, pr_m=g["pr_m"],
                        clock_index=g["clock_index"])  # fmt: skip
    return epochs, meas
