"""Android ``Raw`` measurements (GnssClock + GnssMeasurement) → pseudoranges, rates and C/N0 per signal.

The standard construction (Android's ``GnssMeasurement`` documentation; Google's GPS Measurement Tools):

* receiver time in the GNSS scale: t_rx = TimeNanos + TimeOffsetNanos − (FullBiasNanos + BiasNanos),
  nanoseconds since the GPS epoch (1980-01-06);
* the satellite's transmit time ``ReceivedSvTimeNanos`` counts in each system's own period, so t_rx is
  brought into the same period: GPS, QZSS, Galileo (TOW known): time of week; BeiDou: time of week of
  BDT (GPS − 14 s); GLONASS: time of day in Moscow time (UTC + 3 h, GPS − leap seconds + 3 h);
  Galileo with only the E1C secondary code locked: within its 100 ms period (the flight time, 67–97 ms,
  is shorter, so the ambiguity resolves on its own);
* pseudorange = (t_rx − ReceivedSvTimeNanos) · c, in integer nanoseconds for the whole part (the
  ~10¹⁸ ns counts need all 64 bits) plus the sub-nanosecond fractions.

A measurement is used only when its tracking ``State`` says the transmit time is whole: code lock and
time of week decoded/known, not millisecond-ambiguous (GPS, QZSS, BeiDou GEO and MEO — the GEO D2
navigation message sets the same TOW bits); GLONASS time of day decoded/known; Galileo TOW, or the
E1C secondary code for the 100 ms form. Anything else (SBAS, NavIC, a state without those bits, a
transmit-time uncertainty above ``MAX_TIME_UNCERTAINTY_NS``, a pseudorange outside the physical range) is
kept with ``pr_valid`` false and the reason in ``pr_invalid_why``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import sv_labels
from tollcli.readers.gps_time import LEAP_SECONDS
from tollcli.readers.gsdc import ANDROID_CONSTELLATION

C_MPS = 299_792_458.0
WEEK_NS = 604_800 * 10**9
DAY_NS = 86_400 * 10**9
GAL_E1C_PERIOD_NS = 100_000_000
BDT_MINUS_GPS_NS = -14 * 10**9
MOSCOW_NS = 3 * 3600 * 10**9
#: transmit times known worse than this (ns; 500 ns = 150 m) make no pseudorange
MAX_TIME_UNCERTAINTY_NS = 500.0
#: a pseudorange outside these (m) is not a satellite's: MEO ≈ 19 000–26 000 km, BeiDou GEO/IGSO up to ≈ 42 000 km
PHYSICAL_RANGE_M = (1.8e7, 4.4e7)

# Android GnssMeasurement.getState() bits
STATE_CODE_LOCK = 1
STATE_TOW_DECODED = 8
STATE_MSEC_AMBIGUOUS = 16
STATE_GLO_TOD_DECODED = 128
STATE_GAL_E1BC_CODE_LOCK = 1024
STATE_GAL_E1C_2ND_CODE_LOCK = 2048
STATE_TOW_KNOWN = 16384
STATE_GLO_TOD_KNOWN = 32768


def signal_names(constellation: np.ndarray, carrier_hz: np.ndarray) -> np.ndarray:
    """The signal band of each measurement from its carrier (L1, L5, E1, E5a, G1, B1I, B1C, B2a; '' unknown)."""
    mhz = np.round(np.asarray(carrier_hz, float) / 1e6, 1)
    out = np.full(mhz.shape, "", dtype=object)
    gps_like = np.isin(constellation, ["GPS", "QZSS", "SBAS", "NavIC"])
    out[gps_like & (np.abs(mhz - 1575.4) < 1)] = "L1"
    out[gps_like & (np.abs(mhz - 1176.5) < 1)] = "L5"
    gal = constellation == "Galileo"
    out[gal & (np.abs(mhz - 1575.4) < 1)] = "E1"
    out[gal & (np.abs(mhz - 1176.5) < 1)] = "E5a"
    out[(constellation == "GLONASS") & (mhz > 1597) & (mhz < 1607)] = "G1"
    bds = constellation == "BeiDou"
    out[bds & (np.abs(mhz - 1561.1) < 1)] = "B1I"
    out[bds & (np.abs(mhz - 1575.4) < 1)] = "B1C"
    out[bds & (np.abs(mhz - 1176.5) < 1)] = "B2a"
    return out


def leap_seconds_at(gps_ns: np.ndarray) -> np.ndarray:
    """GPS − UTC (s) at GPS nanoseconds since 1980 (the leap-second table)."""
    leap = np.zeros(np.shape(gps_ns), dtype=np.int64)
    for date, seconds in LEAP_SECONDS:
        start = (np.datetime64(date, "ns") - np.datetime64("1980-01-06", "ns")).astype(np.int64) + seconds * 10**9
        leap = np.where(gps_ns >= start, seconds, leap)
    return leap


def raw_pseudoranges(raw: pd.DataFrame) -> pd.DataFrame:
    """One row per ``Raw`` record: epoch time, satellite, signal, pseudorange (m), rate (m/s), σs, C/N0, validity.

    Columns: ``time_nanos`` and ``epoch_key`` (the epoch's receiver clock count), ``t_rx_gps_s`` (receiver time,
    s since 1980 in GPS time), ``constellation``, ``svid``, ``sv`` (``G05``), ``signal``, ``pr_m``,
    ``pr_sigma_m``, ``prr_mps``, ``prr_sigma_mps``, ``cn0_dbhz``, ``pr_valid``, ``pr_invalid_why``, ``line``.
    """
    def ints(name: str) -> np.ndarray:
        return raw[name].to_numpy(dtype=np.int64, na_value=np.iinfo(np.int64).min)

    def floats(name: str, fill: float = np.nan) -> np.ndarray:
        return pd.to_numeric(raw[name], errors="coerce").fillna(fill).to_numpy(float) if name in raw else np.full(len(raw), fill)

    time_nanos, full_bias, rx_sv = ints("TimeNanos"), ints("FullBiasNanos"), ints("ReceivedSvTimeNanos")
    missing = (time_nanos == np.iinfo(np.int64).min) | (full_bias == np.iinfo(np.int64).min) | (rx_sv == np.iinfo(np.int64).min)
    whole = time_nanos - full_bias  # integer ns since 1980 (GPS time), before the sub-ns fractions
    frac = floats("TimeOffsetNanos", 0.0) - floats("BiasNanos", 0.0)
    state = raw["State"].to_numpy(np.int64)
    code = raw["ConstellationType"].to_numpy(np.int64)
    constellation = pd.Series(code).map(ANDROID_CONSTELLATION).fillna("unknown").to_numpy(object)

    tow = np.mod(whole, WEEK_NS)
    period = np.full(whole.shape, WEEK_NS, dtype=np.int64)
    t_in_period = tow.copy()
    bds = constellation == "BeiDou"
    t_in_period[bds] = np.mod(whole[bds] + BDT_MINUS_GPS_NS, WEEK_NS)
    glo = constellation == "GLONASS"
    glo_tod = np.mod(whole - leap_seconds_at(whole) * 10**9 + MOSCOW_NS, DAY_NS)
    t_in_period[glo] = glo_tod[glo]
    period[glo] = DAY_NS
    tow_known = (state & (STATE_TOW_DECODED | STATE_TOW_KNOWN)) != 0
    gal = constellation == "Galileo"
    gal_short = gal & ~tow_known & ((state & STATE_GAL_E1C_2ND_CODE_LOCK) != 0)
    t_in_period[gal_short] = np.mod(whole[gal_short], GAL_E1C_PERIOD_NS)
    period[gal_short] = GAL_E1C_PERIOD_NS
    diff = np.mod(t_in_period - rx_sv, period)  # the flight time, whole ns (rolled over at the period)
    pr_m = (diff.astype(float) + frac) * (C_MPS * 1e-9)

    code_lock = (state & (STATE_CODE_LOCK | STATE_GAL_E1BC_CODE_LOCK)) != 0
    time_whole = np.select(
        [np.isin(constellation, ["GPS", "QZSS", "BeiDou"]), glo, gal],
        [tow_known & ((state & STATE_MSEC_AMBIGUOUS) == 0),
         (state & (STATE_GLO_TOD_DECODED | STATE_GLO_TOD_KNOWN)) != 0,
         tow_known | gal_short],
        False,
    )  # fmt: skip
    unc_ns = floats("ReceivedSvTimeUncertaintyNanos")
    physical = (pr_m > PHYSICAL_RANGE_M[0]) & (pr_m < PHYSICAL_RANGE_M[1])
    why = np.select(
        [missing, ~np.isin(constellation, ["GPS", "QZSS", "BeiDou", "GLONASS", "Galileo"]), ~code_lock, ~time_whole,
         ~(unc_ns <= MAX_TIME_UNCERTAINTY_NS), ~physical],
        ["clock fields missing", "constellation not used", "no code lock", "transmit time not whole (tracking state)",
         "transmit time uncertain", "pseudorange outside the physical range"],
        "",
    )  # fmt: skip
    svid = raw["Svid"].to_numpy(np.int64)
    # the epoch's receiver time (TimeNanos − FullBiasNanos − BiasNanos): whole seconds + the rest
    t_rx_gps_s = (whole // 10**9).astype(float) + (np.mod(whole, 10**9) - floats("BiasNanos", 0.0)) * 1e-9
    carrier = floats("CarrierFrequencyHz")
    return pd.DataFrame({
        "time_nanos": time_nanos,
        "epoch_key": time_nanos,
        "t_rx_gps_s": np.where(missing, np.nan, t_rx_gps_s),
        "constellation": constellation,
        "svid": svid,
        "sv": sv_labels(constellation, svid),
        "signal": signal_names(constellation, carrier),
        "carrier_hz": carrier,
        "pr_m": np.where(missing, np.nan, pr_m),
        "pr_sigma_m": unc_ns * (C_MPS * 1e-9),
        "prr_mps": floats("PseudorangeRateMetersPerSecond"),
        "prr_sigma_mps": floats("PseudorangeRateUncertaintyMetersPerSecond"),
        "cn0_dbhz": floats("Cn0DbHz"),
        "pr_valid": why == "",
        "pr_invalid_why": why,
        "line": raw["line"].to_numpy(np.int64) if "line" in raw else np.arange(len(raw)) + 1,
    })  # fmt: skip
