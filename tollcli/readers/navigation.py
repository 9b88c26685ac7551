"""The receivers' own solutions, whatever the protocol: NMEA, u-blox NAV messages, gpsd JSON → one kind of table.

Each kind's reader gives the same epoch and satellite tables (:mod:`tollcli.readers.nmea.tables`), chunk by
chunk; everything after the reader (the integrity checks, the charging, the findings) reads them alike.
"""

from __future__ import annotations

import datetime as dt
import os
from collections.abc import Iterator
from typing import BinaryIO

from tollcli.io.sources import BLOCK_BYTES
from tollcli.readers.nmea import NmeaTables, ReadStats, iter_nmea_tables
from tollcli.readers.nmea.reader import CHUNK_EPOCHS

#: the input kinds read as a receiver's own solution (the others are pseudorange logs the tool solves itself)
NAVIGATION_KINDS = ("nmea", "ubx-nav", "gpsd-json", "rtklib-pos")
#: what each kind's messages are called in summaries
PROTOCOL_NAMES = {"nmea": "NMEA sentences", "ubx-nav": "UBX messages", "gpsd-json": "gpsd JSON reports",
                  "rtklib-pos": "RTKLIB solutions"}


def iter_navigation_tables(source: str | os.PathLike | BinaryIO, kind: str = "nmea", *, strict: bool = False,
                           date: dt.date | None = None, stats: ReadStats | None = None, chunk_epochs: int = CHUNK_EPOCHS,
                           block_bytes: int = BLOCK_BYTES) -> Iterator[NmeaTables]:  # fmt: skip
    """The epoch and satellite tables of a log of one of :data:`NAVIGATION_KINDS`, chunk by chunk.

    ``date`` (the UTC date of the first epoch) matters only for NMEA logs without RMC/ZDA: u-blox and gpsd
    give full times."""
    stats = stats if stats is not None else ReadStats()
    stats.protocol = PROTOCOL_NAMES.get(kind, stats.protocol)
    if kind == "ubx-nav":
        from tollcli.readers.ubx_nav import iter_ubx_nav_tables

        return iter_ubx_nav_tables(source, strict=strict, stats=stats, chunk_epochs=chunk_epochs)
    if kind == "gpsd-json":
        from tollcli.readers.gpsd_json import iter_gpsd_json_tables

        return iter_gpsd_json_tables(source, strict=strict, stats=stats, chunk_epochs=chunk_epochs)
    if kind == "rtklib-pos":
        from tollcli.readers.rtklib_pos import iter_rtklib_pos_tables

        return iter_rtklib_pos_tables(source, strict=strict, stats=stats, chunk_epochs=chunk_epochs)
    if kind != "nmea":
        raise ValueError(f"{kind} is not a navigation kind ({', '.join(NAVIGATION_KINDS)})")
    return iter_nmea_tables(source, strict=strict, date=date, stats=stats, chunk_epochs=chunk_epochs, block_bytes=block_bytes)


def iter_epoch_tables(run, strict: bool = False, date: dt.date | None = None, stats: ReadStats | None = None,
                      engine: str = "bulk", decode_ahead: bool = False) -> Iterator[NmeaTables]:  # fmt: skip
    """A log's epoch and satellite tables, chunk by chunk, through its :class:`~tollcli.io.log_run.LogRun` (``epochs``):
    NMEA (and what is nothing else: its errors say why) by the NMEA reader's ``engine``, the other receiver solutions
    by their readers. ``decode_ahead``: see :func:`~tollcli.readers.nmea.reader.iter_nmea_tables`."""
    stats = stats if stats is not None else ReadStats()
    with run.named_errors():
        if run.kind not in NAVIGATION_KINDS or run.kind == "nmea":
            yield from iter_nmea_tables(run.stream(), strict=strict, date=date, stats=stats, engine=engine, decode_ahead=decode_ahead)
        else:
            yield from iter_navigation_tables(run.stream(), run.kind, strict=strict, stats=stats)
