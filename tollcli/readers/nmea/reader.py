"""Read an NMEA 0183 log into columnar epoch and satellite tables, in chunks.

>>> tables = read_nmea("drive.nmea")            # doctest: +SKIP
>>> tables.epochs[["time_utc", "lat_deg", "lon_deg", "hdop"]]   # doctest: +SKIP

What cannot be used is skipped and counted in :class:`ReadStats` (bad
checksums, missing checksums, malformed fields, non-NMEA bytes); with
``strict=True`` the first such line raises :class:`~tollcli.errors.DataError`
naming the file and line.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from tollcli.errors import DataError, PartialError
from tollcli.io.sources import (
    BLOCK_BYTES,
    iter_byte_blocks,
    iter_text_blocks,
    open_binary,
    source_name,
)
from tollcli.readers.nmea.assembler import EpochAssembler
from tollcli.readers.nmea.bulk_reader import BulkReader, Decoded
from tollcli.readers.nmea.dates import DateCarry, first_own_date_contradiction, resolve_days, to_time_utc_ms
from tollcli.readers.nmea.joined_blocks import join_blocks, satellite_rows
from tollcli.readers.nmea.line_reader import ReadStats, feed_lines
from tollcli.io.columns import Columns, as_columns
from tollcli.io.prefetch import read_ahead
from tollcli.readers.nmea.tables import epoch_columns, satellite_columns

#: epochs per chunk handed downstream
CHUNK_EPOCHS = 20_000
#: epochs held back waiting for a date (RMC/ZDA) before giving up on dating them
MAX_UNDATED_EPOCHS = 100_000


class NmeaTables:
    """The two tables of a log: one row per epoch, one per satellite and epoch.

    Built from :class:`~tollcli.io.columns.Columns` (or DataFrames; the satellite table may also be given as a
    function that builds it, called on first use); ``epochs`` and ``satellites`` are pandas DataFrames, converted on
    first use, and ``epoch_columns`` and ``satellite_columns`` the arrays, so that what only writes or counts the
    tables (``tollcli epochs``, ``info``) never imports pandas, nor builds a satellite table it does not write."""

    __slots__ = ("_epochs", "_satellites", "stats")

    def __init__(self, epochs, satellites, stats: ReadStats | None = None):
        self._epochs, self._satellites, self.stats = epochs, satellites, stats

    @property
    def epochs(self):
        if isinstance(self._epochs, Columns):
            self._epochs = self._epochs.to_pandas()
        return self._epochs

    @epochs.setter
    def epochs(self, frame) -> None:
        self._epochs = frame

    def _built_satellites(self):
        if callable(self._satellites):
            self._satellites = self._satellites()
        return self._satellites

    @property
    def satellites(self):
        self._built_satellites()
        if isinstance(self._satellites, Columns):
            self._satellites = self._satellites.to_pandas()
        return self._satellites

    @satellites.setter
    def satellites(self, frame) -> None:
        self._satellites = frame

    @property
    def satellites_read(self):
        """The satellite table as the reader made it: :class:`~tollcli.io.columns.Columns`, or a DataFrame where the
        reader built one (what reads its numbers only, :func:`~tollcli.io.columns.column_array`, needs no frame)."""
        return self._built_satellites()

    @property
    def epoch_columns(self) -> Columns:
        return as_columns(self._epochs)

    @property
    def satellite_columns(self) -> Columns:
        return as_columns(self._built_satellites())


def read_nmea(source: str | os.PathLike | BinaryIO, **options) -> NmeaTables:
    """Read a whole log into memory (for small logs and tests); see :func:`iter_nmea_tables`."""
    stats = options.pop("stats", None) or ReadStats()
    chunks = list(iter_nmea_tables(source, stats=stats, **options))
    if not chunks:
        return NmeaTables(epoch_columns(None), satellite_columns(None, None), stats)
    import pandas as pd

    epochs = pd.concat([c.epochs for c in chunks], ignore_index=True)
    sats = pd.concat([c.satellites for c in chunks], ignore_index=True)
    return NmeaTables(epochs, sats, stats)


def iter_nmea_tables(
    source: str | os.PathLike | BinaryIO,
    *,
    strict: bool = False,
    date: _dt.date | None = None,
    chunk_epochs: int = CHUNK_EPOCHS,
    block_bytes: int = BLOCK_BYTES,
    stats: ReadStats | None = None,
    engine: str = "bulk",
    decode_ahead: bool = False,
) -> Iterator[NmeaTables]:
    """Yield the log's tables chunk by chunk (each chunk ≈ ``chunk_epochs`` epochs).

    ``date``: the UTC date of the first epoch, for logs without RMC/ZDA.
    ``block_bytes``: bytes read at a time (chunks are cut at block ends).
    ``stats`` (optional) is filled in as lines are read.
    ``engine``: ``"bulk"`` (the fast path, :mod:`tollcli.readers.nmea.bulk_reader`) or
    ``"reference"`` (one line at a time; the bulk path is tested against it).
    ``decode_ahead``: the bulk reader decodes the next block on a thread of its own while this one's epochs are
    assembled (:func:`_bulk_chunks`) — for a caller whose work is the reading (``tollcli epochs``).
    """
    stats = stats if stats is not None else ReadStats()
    name = source_name(source)
    stats.source = name
    carry = DateCarry()
    if date is not None:
        carry.last_day = carry.given_day = (date - _dt.date(1970, 1, 1)).days
    pending: list[dict[str, np.ndarray]] = []
    stream = open_binary(source)
    if engine == "bulk":
        try:
            yield from _bulk_chunks(stream, name, stats, strict, chunk_epochs, block_bytes, pending, carry, decode_ahead)
        finally:
            if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
                stream.close()
        return
    if engine != "reference":
        raise ValueError(f"engine {engine!r}: 'bulk' or 'reference'")
    asm = EpochAssembler()
    try:
        for lines in iter_text_blocks(stream, name, block_bytes):
            feed_lines(lines, asm, stats, strict, name)
            if asm.n_ready >= chunk_epochs:
                yield from _emit(_all_per_line(asm.take(), stats), pending, carry, stats, final=False)
        asm.finish()
        yield from _emit(_all_per_line(asm.take(), stats), pending, carry, stats, final=True)
    finally:
        if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
            stream.close()


def _all_per_line(arrays: dict[str, np.ndarray], stats: ReadStats) -> dict[str, np.ndarray]:
    stats.per_line_epochs += arrays["epoch"].size  # the reference reader: every epoch line by line
    return arrays


def _bulk_chunks(stream, name, stats, strict, chunk_epochs, block_bytes, pending, carry, decode_ahead) -> Iterator[NmeaTables]:
    """The bulk reader's two stages over the log's blocks; with ``decode_ahead`` a block apart, the next block decoded
    on a thread of its own while this one's epochs are assembled and dated (:func:`~tollcli.io.prefetch.read_ahead`;
    not with ``TOLLCLI_READ_AHEAD=0``). The tables are the same either way: each stage sees the blocks in order, and
    the decoding never reads what the assembling writes (``tests/test_bulk_reader.py``).

    Where checks follow the reading (``process``, ``integrity``) they hold the second core: a third thread bought no
    time there and held 36 MB more (``process`` of the u-blox mix of ``benchmarks/process_throughput.py``, 6 pairs,
    wall ratio 1.00, peak 364 against 328 MiB); for ``tollcli epochs`` it is a fifth to a quarter of the time."""
    bulk = BulkReader(stats, strict, name)
    ready: list[dict[str, np.ndarray]] = []
    n_ready = 0
    decoded = _decoded_blocks(bulk, iter_byte_blocks(stream, name, block_bytes))
    with read_ahead(decoded) if decode_ahead else contextlib.nullcontext(decoded) as steps:
        for step in steps:
            arrays, step = bulk.take(step), None  # (the decoded block let go before the next is decoded)
            if arrays is not None:
                ready.append(arrays)
                n_ready += arrays["epoch"].size
            if n_ready >= chunk_epochs:
                yield from _emit(join_blocks(ready), pending, carry, stats, final=False)
                ready, n_ready = [], 0
    yield from _emit(join_blocks(ready), pending, carry, stats, final=True)


def _decoded_blocks(bulk: BulkReader, blocks: Iterator[bytes]) -> Iterator[Decoded]:
    """The decoding stage over a log's blocks, and its end."""
    for block in blocks:
        yield bulk.decode(block)
    yield bulk.decode_end()


def _emit(
    arrays: dict[str, np.ndarray],
    pending: list[dict[str, np.ndarray]],
    carry: DateCarry,
    stats: ReadStats,
    final: bool,
) -> Iterator[NmeaTables]:
    """Date the finished epochs and yield them as tables (or hold them for a date)."""
    if carry.last_day < 0 and not (arrays["date_days"] >= 0).any():
        pending.append(arrays)
        held = sum(a["epoch"].size for a in pending)
        if not final and held < MAX_UNDATED_EPOCHS:
            return
    if pending and pending[-1] is arrays:
        pending.pop()
    if pending:
        arrays = {k: np.concatenate([p[k] for p in pending] + [arrays[k]]) for k in arrays}
        pending.clear()
    if arrays["epoch"].size == 0:
        return
    wrong = first_own_date_contradiction(arrays["tod_s"], arrays["date_days"], carry)
    if wrong is not None:
        row, own, counted = wrong
        day = _dt.date(1970, 1, 1).toordinal()
        raise DataError(f"{stats.source}:{int(arrays['line'][row])}: --date says {_dt.date.fromordinal(day + counted).isoformat()} "
                        f"here, the log's own date is {_dt.date.fromordinal(day + own).isoformat()}: leave --date out "
                        f"(it is for logs without RMC/ZDA dates)")  # fmt: skip
    days, arrays["date_jump_days"] = resolve_days(arrays["tod_s"], arrays["date_days"], carry)
    time_utc = to_time_utc_ms(days, arrays["tod_s"])
    epochs = epoch_columns(arrays, time_utc)
    stats.epochs += len(epochs)
    stats.satellite_rows += satellite_rows(arrays)
    stats.undated_epochs += int((days < 0).sum())
    yield NmeaTables(epochs, lambda: satellite_columns(arrays, time_utc), stats)  # built when asked for


def check_partial(stats: ReadStats, max_bad: int | None) -> None:
    """Raise PartialError (exit 3) when more lines were skipped than ``--max-bad`` allows."""
    if max_bad is not None and stats.skipped > max_bad:
        first = f" (first: {stats.first_problem})" if stats.first_problem else ""
        raise PartialError(f"{stats.source}: {stats.skipped} lines skipped, more than --max-bad {max_bad}{first}; outputs were written")


def check_usable(stats: ReadStats) -> None:
    """Raise DataError when a log gave nothing a toll processor can use."""
    if stats.lines == 0:
        if stats.bytes_read:
            raise DataError(f"{stats.source}: no {stats.protocol} in {stats.bytes_read} bytes (no whole frame with a good checksum)")
        raise DataError(f"{stats.source}: empty file")
    if stats.sentences == 0:
        hint = f"; first problem at {stats.first_problem}" if stats.first_problem else ""
        if stats.protocol != "NMEA sentences":
            raise DataError(f"{stats.source}: no {stats.protocol} in {stats.lines} lines or frames{hint}")
        raise DataError(f"{stats.source}: no NMEA sentences in {stats.lines} lines (not an NMEA log? a binary protocol gpsd decodes — "
                        f"SiRF, Javad GREIS, Oncore, … — is read through gpsd's gpsdecode: tollcli runs it where it is installed "
                        f"(Debian: gpsd-clients), or pipe: gpsdecode < {stats.source} | tollcli integrity -){hint}")  # fmt: skip
    if stats.epochs == 0:
        if stats.protocol != "NMEA sentences":
            raise DataError(f"{stats.source}: {stats.sentences} {stats.protocol} but no epoch with a position")
        raise DataError(
            f"{stats.source}: {stats.sentences} NMEA sentences but no epoch: no GGA/RMC/GLL/GNS/ZDA gave a time of day"
        )
