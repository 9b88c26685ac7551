"""Rows of epochs and satellites from a non-NMEA navigation stream (u-blox NAV, gpsd JSON) → the NMEA tables.

Readers of receivers' own solutions (:mod:`tollcli.readers.ubx_nav`, :mod:`tollcli.readers.gpsd_json`) give
the same two tables as the NMEA reader (:mod:`tollcli.readers.nmea.tables`), so the integrity checks, the
charging and the findings read every protocol alike. A reader appends one epoch at a time with the fields its
messages carry (the others stay unknown: NaN, -1) and the satellites of that epoch, and takes the tables
every ``chunk_epochs`` epochs: memory is a chunk's, not the log's.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from tollcli.errors import DataError
from tollcli.io.sources import iter_text_blocks, open_binary, source_name
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.nmea.reader import NmeaTables
from tollcli.readers.nmea.satellite_ids import CONSTELLATIONS
from tollcli.readers.nmea.tables import EPOCH_COLUMNS, epoch_columns, satellite_columns

_INT_FIELDS = {"fix_quality": -1, "fix_mode": -1, "n_used": -1, "n_in_view": -1, "gbs_failed_svid": -1}
_SAT_FIELDS = ("sat_epoch", "sat_constellation", "sat_svid", "sat_prn", "sat_signal_id", "sat_elev_deg", "sat_azim_deg",
               "sat_cn0_dbhz", "sat_used", "sat_residual_m")  # fmt: skip
CONSTELLATION_CODE = {name: i for i, name in enumerate(CONSTELLATIONS)}


class TableBuilder:
    """Epoch and satellite rows appended one epoch at a time; :meth:`take` gives them as the NMEA tables."""

    def __init__(self, stats: ReadStats) -> None:
        self.stats = stats
        self.n_epochs = 0  # epochs taken before (the running ``epoch`` index)
        self._reset()

    def _reset(self) -> None:
        self.rows: list[dict] = []
        self.time_ms: list[int] = []  # ms since 1970 (UTC); -2**63 unknown
        self.sats: dict[str, list] = {k: [] for k in _SAT_FIELDS}

    def __len__(self) -> int:
        return len(self.rows)

    def add_epoch(self, time_ms: int | None, line: int, **fields) -> int:
        """Append an epoch (``fields``: epoch-table columns; ``time_ms``: UTC ms since 1970 or None); its index."""
        index = self.n_epochs + len(self.rows)
        self.rows.append({"line": line, **fields})
        self.time_ms.append(np.iinfo(np.int64).min if time_ms is None else int(time_ms))
        return index

    def add_satellite(self, epoch: int, constellation: str, svid: int, elev_deg: float, azim_deg: float, cn0_dbhz: float,
                      used: bool, residual_m: float, prn: int = -1) -> None:  # fmt: skip
        s = self.sats
        s["sat_epoch"].append(epoch)
        s["sat_constellation"].append(CONSTELLATION_CODE.get(constellation, CONSTELLATION_CODE["unknown"]))
        s["sat_svid"].append(svid)
        s["sat_prn"].append(prn)
        s["sat_signal_id"].append(-1)
        s["sat_elev_deg"].append(elev_deg)
        s["sat_azim_deg"].append(azim_deg)
        s["sat_cn0_dbhz"].append(cn0_dbhz)
        s["sat_used"].append(used)
        s["sat_residual_m"].append(residual_m)

    def take(self) -> NmeaTables | None:
        """The rows so far as tables (None when there are none); the builder starts afresh."""
        if not self.rows:
            return None
        n = len(self.rows)
        arrays: dict[str, np.ndarray] = {"epoch": np.arange(self.n_epochs, self.n_epochs + n, dtype=np.int64)}
        for name in EPOCH_COLUMNS:
            if name in ("epoch", "time_utc"):
                continue
            if name == "mode_indicator":
                arrays[name] = np.array([r.get(name, "") for r in self.rows], dtype=object)
            elif name == "fix_valid":
                arrays[name] = np.array([bool(r.get(name, False)) for r in self.rows])
            elif name == "line":
                arrays[name] = np.array([r["line"] for r in self.rows], dtype=np.int64)
            elif name in _INT_FIELDS:
                arrays[name] = np.array([r.get(name, _INT_FIELDS[name]) for r in self.rows], dtype=np.int64)
            else:
                arrays[name] = np.array([r.get(name, np.nan) for r in self.rows], dtype=float)
        time_ms = np.array(self.time_ms, dtype=np.int64)
        known = time_ms != np.iinfo(np.int64).min
        arrays["tod_s"] = np.where(known, (time_ms % 86_400_000) / 1000.0, arrays["tod_s"])
        time_utc = np.where(known, time_ms, np.iinfo(np.int64).min).astype("datetime64[ms]")
        for key, values in self.sats.items():
            arrays[key] = np.array(values, dtype=bool if key == "sat_used" else float if key.endswith(("_deg", "_dbhz", "_m")) else np.int64)
        epochs = epoch_columns(arrays, time_utc)
        sats = satellite_columns(arrays, time_utc)
        self.stats.epochs += n
        self.stats.satellite_rows += len(sats)
        self.stats.undated_epochs += int((~known).sum())
        self.n_epochs += n
        self._reset()
        return NmeaTables(epochs, sats, self.stats)


def text_line_blocks(source: str | os.PathLike | BinaryIO, stats: ReadStats) -> Iterator[list[tuple[int, str]]]:
    """Blocks of (line number, text stripped) of a text log's non-blank lines, streamed; lines and blanks counted."""
    name = source_name(source)
    stats.source = name
    stream = open_binary(source)
    line_no = 0
    try:
        for lines in iter_text_blocks(stream, name):
            block = []
            for text in lines:
                line_no += 1
                stats.lines += 1
                text = text.strip()
                if text:
                    block.append((line_no, text))
                else:
                    stats.blank += 1
            yield block
    finally:
        if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
            stream.close()


def skip_malformed(stats: ReadStats, line_no: int, what: str, strict: bool) -> None:
    """Count a line that does not parse (the first named in the summary); a DataError under ``--strict``."""
    stats.malformed += 1
    where = f"{stats.source}:{line_no}"
    if not stats.first_problem:
        stats.first_problem = f"{where}: {what}"
    if strict:
        raise DataError(f"{where}: {what}")
