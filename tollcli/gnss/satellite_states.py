"""Satellite positions, velocities and clocks at signal transmission time from broadcast ephemerides.

Shared by every pseudorange input that brings its own navigation data (RINEX navigation files, GPS
LNAV subframes, Galileo I/NAV pages, BeiDou D1 subframes and GLONASS strings decoded from u-blox ``RXM-SFRBX``): an
ephemeris table with the RINEX field names (:data:`tollcli.gnss.orbits.EPHEMERIS_FIELDS` for GPS, Galileo and
BeiDou, :data:`tollcli.gnss.glonass_orbits.GLONASS_FIELDS` for GLONASS, plus ``sv``, ``toc_s``, ``toe_s``,
``group_delay_s`` and ``health``) → for each (satellite, receive time, pseudorange) the ephemeris nearest in time
(GLONASS's within 30 minutes, the others' within 4 hours), the
transmission time t_tx = t_rx − pr/c − dt_sv (iterated), and at t_tx the ECEF position (m, in the frame
of t_tx), velocity (m/s, central difference over ±``DIFF_S``), clock offset (s) and drift (s/s).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.gnss.glonass_orbits import GLONASS_FIELDS, glonass_position_clock
from tollcli.gnss.glonass_orbits import MAX_AGE_S as GLONASS_MAX_AGE_S
from tollcli.gnss.orbits import EPHEMERIS_FIELDS, WEEK_S, kepler_position_clock
from tollcli.gnss.beidou_d1 import BDT_GPS_S, BDT_WEEK_OFFSET, is_geostationary
from tollcli.readers.gps_time import gps_seconds, leap_seconds_at_gps

C_MPS = 299_792_458.0
#: half-step of the central difference for velocity and clock drift (s): errors ≪ 1 mm/s
DIFF_S = 0.05
#: an ephemeris further than this from the query (s) is not used (broadcast fit intervals are 4 h)
MAX_AGE_S = 4 * 3600.0


class NoOrbitForRows(DataError):
    """None of a set of measurements has a satellite orbit (the navigation data are of another time, or none). Read
    whole, a log without one is an error; a segment of a longer log (:mod:`tollcli.job.pseudorange_segments`) is
    solved without positions instead, as the same epochs are within the whole log."""


def rinex_ephemeris_table(nav) -> pd.DataFrame:
    """A georinex navigation dataset (RINEX 2 or 3: GPS, Galileo, BeiDou, GLONASS) as one ephemeris per row.

    Epochs are in each system's time: GPS and Galileo as GPS time, BeiDou in BDT (GPS − 14 s; its week
    ``BDTWeek`` counts from 2006), GLONASS in UTC (its state vector in km, km/s and km/s² in the file, metres in georinex's dataset)."""
    table = nav.to_dataframe().reset_index()
    kepler = table["sqrtA"].notna() if "sqrtA" in table else pd.Series(False, index=table.index)
    glonass = table["X"].notna() & table["sv"].astype(str).str.startswith("R") if "X" in table else pd.Series(False, index=table.index)
    table = table[kepler | glonass].copy()  # (a file of other systems only: none)
    if table.empty:
        raise DataError("no GPS, Galileo, BeiDou or GLONASS ephemerides in the navigation file")
    table["sv"] = table["sv"].astype(str)
    system = table["sv"].str[0].to_numpy()
    beidou, glo = system == "C", system == "R"
    epoch = gps_seconds(table["time"].to_numpy())
    table["toc_s"] = np.where(beidou, epoch + BDT_GPS_S, np.where(glo, epoch + leap_seconds_at_gps(epoch), epoch))
    week = table["GPSWeek"].to_numpy(float) if "GPSWeek" in table else np.full(len(table), np.nan)
    if "GALWeek" in table:
        week = np.where(system == "E", table["GALWeek"].to_numpy(float), week)
    if "BDTWeek" in table:
        week = np.where(beidou, table["BDTWeek"].to_numpy(float) + BDT_WEEK_OFFSET, week)
    toe = table["Toe"].to_numpy(float) if "Toe" in table else np.full(len(table), np.nan)
    table["toe_s"] = np.where(glo, table["toc_s"], week * WEEK_S + toe + np.where(beidou, BDT_GPS_S, 0.0))
    gd = table["TGD"].to_numpy(float) if "TGD" in table else np.zeros(len(table))
    if "BGDe5b" in table:
        gd = np.where(system == "E", table["BGDe5b"].to_numpy(float), gd)
    table["group_delay_s"] = np.where(beidou | glo, 0.0, np.nan_to_num(gd))  # BeiDou: B3I's clock (TGD1/TGD2 kept)
    health = table["health"].to_numpy(float) if "health" in table else np.zeros(len(table))
    if "SatH1" in table:
        health = np.where(beidou, table["SatH1"].to_numpy(float), health)
    table["health"] = np.nan_to_num(health)
    if glo.any():  # the state vector in metres (the file's km: georinex scales them)
        for name in ("X", "Y", "Z", "dX", "dY", "dZ", "dX2", "dY2", "dZ2"):
            table[name] = np.where(glo, table[name].to_numpy(float), np.nan)
    return table.reset_index(drop=True)


def navigation_files(nav) -> list[str]:
    """``--nav`` as given (one path, or several) → the list of paths."""
    return [nav] if isinstance(nav, str) else list(nav)


def load_navigation(nav) -> tuple[pd.DataFrame, list | None]:
    """One ephemeris table from one or several RINEX navigation files (``nav``: a path or a list: a day's GPS file
    beside its Galileo file, or consecutive days), and the GPS Klobuchar coefficients of the first file that has
    them. A record broadcast twice (the same satellite and clock time in two files) is kept once, from the first
    file; a file without GPS, Galileo, BeiDou or GLONASS ephemerides is an error naming it."""
    from tollcli.readers.rinex import load_rinex

    tables, iono = [], None
    for path in navigation_files(nav):
        data = load_rinex(path, "navigation")
        try:
            tables.append(rinex_ephemeris_table(data))
        except DataError as exc:
            raise DataError(f"{path}: {exc}") from None
        coeffs = data.attrs.get("ionospheric_corr_GPS")
        if iono is None and coeffs is not None and len(coeffs) == 8:
            iono = coeffs
    if len(tables) == 1:
        return tables[0], iono
    table = pd.concat(tables, ignore_index=True).drop_duplicates(["sv", "toc_s"], keep="first")
    return table.sort_values(["sv", "toc_s"], kind="stable").reset_index(drop=True), iono


def nearest_ephemerides(table: pd.DataFrame, sv: np.ndarray, t_s: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per query, the fields of the satellite's ephemeris with the nearest clock reference time, and
    whether there is one (within ``MAX_AGE_S``, a GLONASS one within its 30 minutes, healthy)."""
    table = table.sort_values("toc_s", kind="stable")
    queries = pd.DataFrame({"sv": np.asarray(sv, dtype=str), "t_s": np.asarray(t_s, float), "i": np.arange(len(sv))})
    queries = queries.sort_values("t_s", kind="stable")
    merged = pd.merge_asof(queries, table, left_on="t_s", right_on="toc_s", by="sv", direction="nearest",
                           tolerance=MAX_AGE_S).sort_values("i")  # fmt: skip
    glonass = merged["X"].notna().to_numpy() if "X" in merged else np.zeros(len(merged), bool)
    kepler = merged["sqrtA"].notna().to_numpy() if "sqrtA" in merged else np.zeros(len(merged), bool)
    age = np.abs(merged["t_s"].to_numpy(float) - merged["toc_s"].to_numpy(float))
    have = (kepler | (glonass & (age <= GLONASS_MAX_AGE_S))) & (np.nan_to_num(merged["health"].to_numpy(float)) == 0)
    names = (*EPHEMERIS_FIELDS, *GLONASS_FIELDS, "toc_s", "toe_s", "group_delay_s", "TGD1", "TGD2", "FreqNum")
    n = len(merged)
    eph = {k: merged[k].to_numpy(float) if k in merged else np.full(n, np.nan) for k in names}
    return eph, have


def _position_clock(eph: dict[str, np.ndarray], t_s: np.ndarray, system: np.ndarray, prn: np.ndarray):
    """Position and clock at ``t_s`` of each query, by its system (``system``: the labels' first letters)."""
    pos, clock = kepler_position_clock(eph, t_s, system == "E", system == "C", is_geostationary(prn))
    glonass = system == "R"
    if glonass.any():
        sub = {k: v[glonass] for k, v in eph.items()}
        with np.errstate(invalid="ignore"):
            g_pos, g_clock = glonass_position_clock(sub, t_s[glonass])
        pos[glonass], clock[glonass] = g_pos, g_clock
    return pos, clock


def satellite_states(table: pd.DataFrame, sv: np.ndarray, t_rx_s: np.ndarray, pr_m: np.ndarray) -> dict[str, np.ndarray]:
    """ECEF state of each satellite at its transmission time.

    Returns ``pos_m`` (n, 3), ``vel_mps`` (n, 3), ``clock_s`` (n,) (relativity and group delay included),
    ``drift_sps`` (n,), ``t_tx_s`` (n,), ``have`` (n,) — false where no usable ephemeris is known — and the BeiDou
    ephemeris's group delays ``tgd1_s``/``tgd2_s`` (B1I and B2I against B3I, to which its clock refers; NaN else)
    and a GLONASS ephemeris's frequency number ``freq_num`` (NaN else).
    """
    sv = np.asarray(sv, dtype=str)
    t_rx_s, pr_m = np.asarray(t_rx_s, float), np.asarray(pr_m, float)
    eph, have = nearest_ephemerides(table, sv, t_rx_s)
    system = sv.astype("<U1")  # the labels' first letters
    prn = pd.to_numeric(pd.Series(sv, dtype=object).str[1:3], errors="coerce").fillna(0).to_numpy(np.int64)
    t_tx = t_rx_s - pr_m / C_MPS
    with np.errstate(invalid="ignore"):
        for _ in range(3):
            _, clock = _position_clock(eph, t_tx, system, prn)
            t_tx = t_rx_s - pr_m / C_MPS - clock
        pos, clock = _position_clock(eph, t_tx, system, prn)
        ahead, clock_ahead = _position_clock(eph, t_tx + DIFF_S, system, prn)
        behind, clock_behind = _position_clock(eph, t_tx - DIFF_S, system, prn)
    vel = (ahead - behind) / (2 * DIFF_S)
    drift = (clock_ahead - clock_behind) / (2 * DIFF_S)
    have = have & np.isfinite(pos).all(axis=1) & np.isfinite(clock)
    return {"pos_m": pos, "vel_mps": vel, "clock_s": clock, "drift_sps": drift, "t_tx_s": t_tx, "have": have,
            "tgd1_s": eph["TGD1"], "tgd2_s": eph["TGD2"], "freq_num": eph["FreqNum"]}
