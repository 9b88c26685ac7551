"""Satellite positions, velocities and clocks at signal transmission time from broadcast ephemerides.

Shared by every pseudorange input that brings its own navigation data (RINEX navigation files, GPS
LNAV subframes decoded from u-blox ``RXM-SFRBX``): an ephemeris table with the RINEX field names
(:data:`tollcli.gnss.orbits.EPHEMERIS_FIELDS` plus ``sv``, ``toc_s``, ``toe_s``, ``group_delay_s`` and
``health``) → for each (satellite, receive time, pseudorange) the ephemeris nearest in time, the
transmission time t_tx = t_rx − pr/c − dt_sv (iterated), and at t_tx the ECEF position (m, in the frame
of t_tx), velocity (m/s, central difference over ±``DIFF_S``), clock offset (s) and drift (s/s).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.gnss.orbits import EPHEMERIS_FIELDS, WEEK_S, kepler_position_clock
from tollcli.readers.gps_time import gps_seconds

C_MPS = 299_792_458.0
#: half-step of the central difference for velocity and clock drift (s): errors ≪ 1 mm/s
DIFF_S = 0.05
#: an ephemeris further than this from the query (s) is not used (broadcast fit intervals are 4 h)
MAX_AGE_S = 4 * 3600.0


def rinex_ephemeris_table(nav) -> pd.DataFrame:
    """A georinex navigation dataset (RINEX 2 or 3, GPS and Galileo) as one ephemeris per row."""
    table = nav.to_dataframe().reset_index()
    table = table.dropna(subset=["sqrtA"]) if "sqrtA" in table else table.iloc[:0]  # (a file of other systems only: none)
    if table.empty:
        raise DataError("no GPS or Galileo ephemerides in the navigation file")
    table["sv"] = table["sv"].astype(str)
    table["toc_s"] = gps_seconds(table["time"].to_numpy())
    week = table["GPSWeek"] if "GPSWeek" in table else np.nan
    if "GALWeek" in table:
        week = np.where(table["sv"].str.startswith("E"), table["GALWeek"], week)
    table["toe_s"] = np.asarray(week, float) * WEEK_S + table["Toe"].to_numpy(float)
    gd = table["TGD"] if "TGD" in table else 0.0
    if "BGDe5b" in table:
        gd = np.where(table["sv"].str.startswith("E"), table["BGDe5b"], gd)
    table["group_delay_s"] = np.nan_to_num(np.asarray(gd, float))
    table["health"] = np.nan_to_num(table["health"].to_numpy(float)) if "health" in table else 0.0
    return table


def navigation_files(nav) -> list[str]:
    """``--nav`` as given (one path, or several) → the list of paths."""
    return [nav] if isinstance(nav, str) else list(nav)


def load_navigation(nav) -> tuple[pd.DataFrame, list | None]:
    """One ephemeris table from one or several RINEX navigation files (``nav``: a path or a list: a day's GPS file
    beside its Galileo file, or consecutive days), and the GPS Klobuchar coefficients of the first file that has
    them. A record broadcast twice (the same satellite and clock time in two files) is kept once, from the first
    file; a file without GPS or Galileo ephemerides is an error naming it."""
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
    whether there is one (within ``MAX_AGE_S``, healthy)."""
    table = table.sort_values("toc_s", kind="stable")
    queries = pd.DataFrame({"sv": np.asarray(sv, dtype=str), "t_s": np.asarray(t_s, float), "i": np.arange(len(sv))})
    queries = queries.sort_values("t_s", kind="stable")
    merged = pd.merge_asof(queries, table, left_on="t_s", right_on="toc_s", by="sv", direction="nearest",
                           tolerance=MAX_AGE_S).sort_values("i")  # fmt: skip
    have = merged["sqrtA"].notna().to_numpy() & (np.nan_to_num(merged["health"].to_numpy(float)) == 0)
    eph = {k: merged[k].to_numpy(float) for k in (*EPHEMERIS_FIELDS, "toc_s", "toe_s", "group_delay_s")}
    return eph, have


def satellite_states(table: pd.DataFrame, sv: np.ndarray, t_rx_s: np.ndarray, pr_m: np.ndarray) -> dict[str, np.ndarray]:
    """ECEF state of each satellite at its transmission time.

    Returns ``pos_m`` (n, 3), ``vel_mps`` (n, 3), ``clock_s`` (n,) (relativity and group delay included),
    ``drift_sps`` (n,), ``t_tx_s`` (n,) and ``have`` (n,) — false where no usable ephemeris is known.
    """
    sv = np.asarray(sv, dtype=str)
    t_rx_s, pr_m = np.asarray(t_rx_s, float), np.asarray(pr_m, float)
    eph, have = nearest_ephemerides(table, sv, t_rx_s)
    galileo = np.char.startswith(sv, "E")
    t_tx = t_rx_s - pr_m / C_MPS
    for _ in range(3):
        _, clock = kepler_position_clock(eph, t_tx, galileo)
        t_tx = t_rx_s - pr_m / C_MPS - clock
    pos, clock = kepler_position_clock(eph, t_tx, galileo)
    ahead, clock_ahead = kepler_position_clock(eph, t_tx + DIFF_S, galileo)
    behind, clock_behind = kepler_position_clock(eph, t_tx - DIFF_S, galileo)
    vel = (ahead - behind) / (2 * DIFF_S)
    drift = (clock_ahead - clock_behind) / (2 * DIFF_S)
    have = have & np.isfinite(pos).all(axis=1) & np.isfinite(clock)
    return {"pos_m": pos, "vel_mps": vel, "clock_s": clock, "drift_sps": drift, "t_tx_s": t_tx, "have": have}
