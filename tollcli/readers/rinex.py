"""RINEX 3 (and 2) observation and navigation files (georinex), read into tables.

* :func:`load_rinex`: a file as georinex's dataset (GPS, Galileo, GLONASS, BeiDou), with clear errors.
* :func:`observations`: one row per (epoch, satellite) with one code pseudorange per system — GPS L1 C/A, Galileo
  E1, GLONASS G1 C/A, BeiDou B1I (else B3I, else B2I) — its observation code and its C/N0; receiver time in GPS
  time.

Positions and RAIM measurements are made from them in :mod:`tollcli.gnss.rinex_positions`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError

#: the code observations read, in order of preference: RINEX 3 names, then RINEX 2 (C1 the C/A code, P1 the P
#: code); the C/N0 is the S observation of the same band and attribute (S1C, S1 …). BeiDou B1I is C2I from RINEX
#: 3.02 on, C1I before; B3I is C6I, B2I C7I
CODES = {"G": ("C1C", "C1P", "C1W", "C1", "P1"), "E": ("C1C", "C1X", "C1B", "C1"), "R": ("C1C", "C1P", "C1"),
         "C": ("C2I", "C1I", "C6I", "C7I", "C2")}  # fmt: skip
NAMES = {"G": "GPS", "E": "Galileo", "R": "GLONASS", "C": "BeiDou"}


def load_rinex(path: str, what: str):
    """georinex's dataset of a RINEX ``what`` ("observation" or "navigation") file: GPS, Galileo, GLONASS, BeiDou."""
    try:
        import georinex
    except ImportError:  # pragma: no cover - a dependency of the package
        raise UsageError("reading RINEX needs georinex (pip install georinex)") from None
    try:
        with warnings.catch_warnings():  # georinex's own xarray deprecations are not the user's business
            warnings.simplefilter("ignore", FutureWarning)
            warnings.simplefilter("ignore", DeprecationWarning)
            return georinex.load(path, use=set(NAMES))
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except Exception as exc:  # georinex raises many kinds on bad files
        raise DataError(f"{path}: not a readable RINEX {what} file ({type(exc).__name__}: {exc})") from None


def observations(obs) -> pd.DataFrame:
    """One row per (epoch, satellite) with a pseudorange: time, sv, pr_m, cn0_dbhz, code (the observation read)."""
    frames = []
    for system, codes in CODES.items():
        svs = [s for s in obs.sv.values if str(s).startswith(system)]
        code = next((c for c in codes if c in obs and np.isfinite(obs[c].sel(sv=svs).values).any()), None) if svs else None
        if code is None:
            continue
        pr = obs[code].sel(sv=svs).to_pandas()
        snr_name = "S" + code[1:]
        snr = obs[snr_name].sel(sv=svs).to_pandas() if snr_name in obs else pr * np.nan
        table = pd.DataFrame({"pr_m": pr.stack(future_stack=True), "cn0_dbhz": snr.stack(future_stack=True)}).reset_index()
        frames.append(table.rename(columns={table.columns[0]: "time", table.columns[1]: "sv"}).assign(code=code))
    if not frames:
        raise DataError("no GPS, Galileo, GLONASS or BeiDou code observations (RINEX 3: C1C/C1X/C1P/C1W/C1B, BeiDou "
                        "C2I/C1I/C6I/C7I; RINEX 2: C1/P1) in the observation file")  # fmt: skip
    rows = pd.concat(frames, ignore_index=True)
    rows["time"] = rows["time"].astype("datetime64[ns]")  # one unit whatever the RINEX version (georinex: ns for 2, µs for 3)
    return rows[np.isfinite(rows["pr_m"])].sort_values(["time", "sv"], kind="stable").reset_index(drop=True)
