"""RINEX 3 observation + navigation files → WLS positions and RAIM measurements (GPS, Galileo, GLONASS, BeiDou).

* Observations (:mod:`tollcli.readers.rinex_obs`, else :mod:`tollcli.readers.rinex`, the same rows):
  one code pseudorange per system (L1/E1/G1 ``C1C``…, BeiDou B1I
  ``C2I``/``C1I``, else B3I ``C6I``, else B2I ``C7I``) and its C/N0 (``S…``); receiver time from the file (GPS time).
  A BeiDou B1I or B2I code takes its group delay against B3I (TGD1, TGD2), to which the broadcast clock refers.
* Orbits and clocks: the broadcast ephemeris of each satellite nearest in time
  (:mod:`tollcli.gnss.satellite_states`) at the transmission time
  t_tx = t_rx − pr/c − dt_sv, iterated.
* Corrections inside the WLS: satellite clock (+ c·dt_sv, with relativity and
  group delay), Klobuchar ionosphere from the navigation header (GPSA/GPSB),
  Saastamoinen troposphere (the ionosphere scaled by (f_L1/f)² to each carrier); Sagnac in the geometry. One
  receiver clock per constellation (the offsets between the systems' times stay unknowns).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import UsageError
from tollcli.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m
from tollcli.gnss.measurements import Measurements, pad, slots
from tollcli.gnss.orbits import WEEK_S
from tollcli.gnss.pseudorange_wls import C_MPS, final_geometry, solvable, solve_positions
from tollcli.gnss.satellite_states import NoOrbitForRows, load_navigation, navigation_files, satellite_states
from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.readers.gps_time import gps_millis_to_utc, gps_seconds
from tollcli.readers.rinex import NAMES, load_rinex, observations
from tollcli.readers.rinex_obs import observation_rows

#: the systems, in the order their receiver clocks are numbered
SYSTEMS = ("G", "E", "R", "C")
L1_HZ = 1_575_420_000.0
#: carrier (Hz) of each code read (:data:`tollcli.readers.rinex.CODES`); GLONASS G1 adds its channel × 562.5 kHz
CARRIERS_HZ = {"C": {"C2I": 1_561_098_000.0, "C1I": 1_561_098_000.0, "C2": 1_561_098_000.0, "C6I": 1_268_520_000.0,
                     "C7I": 1_207_140_000.0}}  # fmt: skip


def carrier_hz(system: np.ndarray, code: np.ndarray, glonass_channel: np.ndarray | None) -> np.ndarray:
    """The carrier frequency (Hz) of each observation (for the ionosphere's 1/f² scaling): L1/E1 unless BeiDou's
    band or GLONASS's channel (from the navigation file's frequency number; 1602 MHz where it gives none)."""
    out = np.full(system.shape, L1_HZ)
    for c, table in CARRIERS_HZ.items():
        for name, hz in table.items():
            out[(system == c) & (code == name)] = hz
    channel = np.zeros(system.shape) if glonass_channel is None else np.nan_to_num(np.asarray(glonass_channel, float))
    out = np.where(system == "R", 1_602_000_000.0 + channel * 562_500.0, out)
    return out


def check_sigma_model(sigma_model: str) -> None:
    """Refuse a σ model RINEX observations cannot give (``input``: they carry no per-measurement σ)."""
    if sigma_model == "input":
        raise UsageError("--sigma-model input: RINEX observations carry no per-measurement σ; use nominal or constant")


def rinex_epochs(obs_path: str, nav_path, sigma_model: str = "nominal", sigma_m: float = 5.0,
                 nominal: NominalModel | None = None) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """WLS position per epoch (an epoch table) and the RAIM measurements at that position (``nav_path``: one
    navigation file or a list of them, :func:`~tollcli.gnss.satellite_states.load_navigation`)."""
    check_sigma_model(sigma_model)
    rows = observation_rows(obs_path)  # read directly; else (where the two could differ) georinex
    obs = load_rinex(obs_path, "observation") if rows is None else None
    ephemerides, coeffs = load_navigation(nav_path)
    if rows is None:
        rows = observations(obs)
    return rinex_rows_epochs(rows, ephemerides, coeffs, sigma_model, sigma_m, nominal, obs_path, nav_path)


def rinex_rows_epochs(rows: pd.DataFrame, ephemerides: pd.DataFrame, coeffs, sigma_model: str = "nominal", sigma_m: float = 5.0,
                      nominal: NominalModel | None = None, obs_path: str = "", nav_path="",
                      orbits_required: bool = True) -> tuple[pd.DataFrame, Measurements]:  # fmt: skip
    """:func:`rinex_epochs` of observation rows (:func:`tollcli.readers.rinex.observations`' columns) with the
    navigation files' ``ephemerides`` and ionosphere ``coeffs`` (:func:`~tollcli.gnss.satellite_states.load_navigation`);
    ``obs_path`` and ``nav_path`` name the files in an error. Rows none of which has an orbit raise
    :class:`~tollcli.gnss.satellite_states.NoOrbitForRows`, or (``orbits_required`` False) give epochs without
    positions."""
    check_sigma_model(sigma_model)
    t_rx = gps_seconds(rows["time"].to_numpy())
    sv = rows["sv"].to_numpy(str)
    pr = rows["pr_m"].to_numpy(float)
    states = satellite_states(ephemerides, sv, t_rx, pr)
    pos, clock, usable = states["pos_m"], states["clock_s"], states["have"]
    code = rows["code"].to_numpy(object)
    system = sv.astype("<U1")
    b1i, b2i = (system == "C") & np.isin(code, ("C2I", "C1I", "C2")), (system == "C") & (code == "C7I")
    clock = clock - np.where(b1i, np.nan_to_num(states["tgd1_s"]), 0.0) - np.where(b2i, np.nan_to_num(states["tgd2_s"]), 0.0)
    carrier = carrier_hz(system, code, states["freq_num"])
    if not usable.any() and orbits_required:  # a navigation file of another day: say so, not "every epoch insufficient"
        raise NoOrbitForRows(f"{obs_path}: no observation has a satellite orbit in {', '.join(navigation_files(nav_path))} ({orbit_coverage(ephemerides, t_rx)}); "
                             "a navigation file for the day of the observations gives the orbits")  # fmt: skip

    epoch_times, row = np.unique(rows["time"].to_numpy(), return_inverse=True)
    keep = np.flatnonzero(usable)
    row = row[keep]
    slot, n_slots = slots(row, epoch_times.size)
    shape = (epoch_times.size, n_slots)
    mask = pad(np.ones(keep.size, bool), row, slot, shape, False)
    sat = np.stack([pad(pos[keep, k], row, slot, shape, 0.0) for k in range(3)], -1)
    pr_corr = pad(pr[keep] + C_MPS * clock[keep], row, slot, shape, 0.0)
    labels = pad(sv[keep].astype(object), row, slot, shape, "")
    letters = pad(system[keep].astype(object), row, slot, shape, "")
    iono_scale = pad((L1_HZ / carrier[keep]) ** 2, row, slot, shape, 1.0)
    cn0 = pad(rows["cn0_dbhz"].to_numpy(float)[keep], row, slot, shape, np.nan)
    tow = np.mod(gps_seconds(epoch_times), WEEK_S)[:, None]

    def correction(lat, lon, h, elev, azim, rows):
        delay = saastamoinen_delay_m(lat[:, None], h[:, None], elev)
        if coeffs is not None and len(coeffs) == 8:
            delay = delay + iono_scale[rows] * klobuchar_delay_m(lat[:, None], lon[:, None], elev, azim, tow[rows], coeffs[:4], coeffs[4:])
        return delay

    present = [c for c in SYSTEMS if (letters == c).any()]  # one receiver clock per constellation, in SYSTEMS' order
    clock_index = np.zeros(shape, np.int64)
    for k, c in enumerate(present):
        clock_index[letters == c] = k
    x = solve_positions(sat, pr_corr, mask, np.where(mask, sigma_m, np.nan), correction, clock_index)
    g = final_geometry(sat, pr_corr, mask, x, correction, clock_index)
    const = np.full(shape, "GPS", dtype=object)
    for letter, name in NAMES.items():
        const[letters == letter] = name
    sigma = np.where(mask, sigma_for(sigma_model, elev_deg=g["elev_deg"], cn0_dbhz=cn0, constellation=const,
                                     lat_deg=g["lat_deg"][:, None], lon_deg=g["lon_deg"][:, None],
                                     sigma_const_m=sigma_m, nominal=nominal), np.nan)  # fmt: skip
    H = g["H"]
    ok = solvable(mask, clock_index)
    epochs = pd.DataFrame(
        {
            "epoch": np.arange(epoch_times.size, dtype=np.int64),
            "time_utc": pd.DatetimeIndex(gps_millis_to_utc((gps_seconds(epoch_times) * 1000).round().astype(np.int64))).tz_localize("UTC"),
            "time_gps": pd.DatetimeIndex(epoch_times),
            "lat_deg": np.where(ok, g["lat_deg"], np.nan),
            "lon_deg": np.where(ok, g["lon_deg"], np.nan),
            "height_m": np.where(ok, g["height_m"], np.nan),
            "clock_bias_m": np.where(ok, x[:, 3], np.nan),
            "n_measurements": mask.sum(axis=1).astype(np.int16),
        }
    )
    meas = Measurements(H, sigma, mask, labels, dy_m=g["dy_m"], cn0_dbhz=cn0,
                        test_stat_source=np.full(epoch_times.size, "pseudorange", dtype=object), sat_ecef_m=sat, pr_m=g["pr_m"],
                        clock_index=g["clock_index"])  # fmt: skip
    return epochs, meas


def orbit_coverage(ephemerides: pd.DataFrame, t_rx_s: np.ndarray) -> str:
    """When a navigation file's ephemerides and the observations are, in words (UTC dates, GPS time)."""

    def span(t: np.ndarray) -> str:
        a, b = gps_millis_to_utc(np.round(np.array([np.nanmin(t), np.nanmax(t)]) * 1000))
        return f"{str(a)[:16]} – {str(b)[:16]} UTC"

    return f"ephemerides {span(ephemerides['toc_s'].to_numpy(float))}, observations {span(np.asarray(t_rx_s, float))}"
