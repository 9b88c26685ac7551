"""Satellites from a RINEX navigation file (broadcast ephemerides) instead of the nominal constellations.

Per chunk of epochs each satellite uses its ephemeris nearest in time to the chunk's
middle (valid ±4 h); satellites with none are never visible. Times are GPS seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError
from tollcli.gnss.orbits import kepler_position_clock
from tollcli.gnss.satellite_states import nearest_ephemerides, rinex_ephemeris_table
from tollcli.readers.rinex import NAMES, load_rinex

LETTER = {"gps": "G", "galileo": "E"}


@dataclass(frozen=True)
class BroadcastOrbits:
    """The navigation file's GPS/Galileo satellites (arrays of length S)."""

    table: pd.DataFrame  # the ephemerides, one per row (:func:`rinex_ephemeris_table`)
    sv: np.ndarray  # RINEX names, e.g. "G05"
    names: np.ndarray  # constellation names
    svid: np.ndarray

    def ecef(self, t_s, per_satellite: bool = False) -> np.ndarray:
        """ECEF (…, S, 3) at GPS seconds ``t_s`` (last axis per satellite with ``per_satellite``)."""
        t = np.asarray(t_s, dtype=float)
        t = t if per_satellite else np.broadcast_to(t[..., None], t.shape + (self.sv.size,))
        mid = float(np.nanmedian(t))
        eph, have = nearest_ephemerides(self.table, self.sv, np.full(self.sv.size, mid))
        pos, _ = kepler_position_clock(eph, t, self.names == "Galileo")
        return np.where(have[:, None], pos, np.nan)


def load_orbits(path: str, constellations: list[str]) -> BroadcastOrbits:
    """The satellites of ``path`` that belong to ``constellations`` (``gps``, ``galileo``)."""
    nav = load_rinex(path, "navigation")
    letters = {LETTER[c] for c in constellations}
    table = rinex_ephemeris_table(nav)
    sv = np.array(sorted({str(s) for s in table["sv"] if str(s)[:1] in letters}), dtype=object)
    if sv.size == 0:
        raise DataError(f"{path}: no {' or '.join(sorted(constellations))} ephemerides")
    names = np.array([NAMES[s[0]] for s in sv], dtype=object)
    return BroadcastOrbits(table, sv, names, np.array([int(s[1:]) for s in sv]))


def gps_seconds_of(ts: pd.Timestamp) -> float:
    return (pd.Timestamp(ts).tz_convert(None) - pd.Timestamp("1980-01-06")).total_seconds() + 18.0  # GPS − UTC since 2017
