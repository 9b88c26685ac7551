"""Read an NMEA 0183 log into columnar epoch and satellite tables, in chunks.

>>> tables = read_nmea("drive.nmea")            # doctest: +SKIP
>>> tables.epochs[["time_utc", "lat_deg", "lon_deg", "hdop"]]   # doctest: +SKIP

What cannot be used is skipped and counted in :class:`ReadStats` (bad
checksums, missing checksums, malformed fields, non-NMEA bytes); with
``strict=True`` the first such line raises :class:`~tollcli.errors.DataError`
naming the file and line.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np
import pandas as pd

from tollcli.errors import DataError, PartialError
from tollcli.io.sources import (
    BLOCK_BYTES,
    iter_byte_blocks,
    iter_text_blocks,
    open_binary,
    source_name,
)
from tollcli.nmea.assembler import EpochAssembler
from tollcli.nmea.dates import DateCarry, resolve_days, to_time_utc_ms
from tollcli.nmea.fields import checksum
from tollcli.nmea.tables import epoch_frame, satellite_frame

#: epochs per chunk handed downstream
CHUNK_EPOCHS = 20_000
#: epochs held back waiting for a date (RMC/ZDA) before giving up on dating them
MAX_UNDATED_EPOCHS = 100_000
ANDROID_PREFIX = "NMEA,"


@dataclass
class ReadStats:
    """What happened to every line of a log."""

    source: str = ""
    lines: int = 0
    sentences: int = 0  # checksum-verified NMEA sentences
    decoded: int = 0  # of which decoded into epochs
    unused: int = 0  # valid sentences of types the reader does not use (proprietary, AIS, ...)
    comments: int = 0
    blank: int = 0
    bad_checksum: int = 0
    no_checksum: int = 0
    malformed: int = 0
    not_nmea: int = 0
    epochs: int = 0
    satellite_rows: int = 0
    undated_epochs: int = 0
    first_problem: str = ""
    unused_types: dict[str, int] = field(default_factory=dict)

    @property
    def skipped(self) -> int:
        """Lines that could not be used: the count ``--strict`` refuses."""
        return self.bad_checksum + self.no_checksum + self.malformed + self.not_nmea

    def summary(self) -> str:
        """One line for stderr."""
        parts = [
            f"{self.lines} lines",
            f"{self.sentences} NMEA sentences",
            f"{self.epochs} epochs",
            f"{self.satellite_rows} satellite rows",
        ]
        skipped = [
            (self.bad_checksum, "bad checksum"),
            (self.no_checksum, "no checksum"),
            (self.malformed, "malformed"),
            (self.not_nmea, "not NMEA"),
        ]
        detail = ", ".join(f"{n} {what}" for n, what in skipped if n)
        text = f"{self.source}: " + ", ".join(parts)
        if self.skipped:
            text += f"; skipped {self.skipped} lines ({detail})"
        if self.undated_epochs:
            text += f"; {self.undated_epochs} epochs without a date (no RMC/ZDA; use --date)"
        return text

    def as_dict(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out["skipped"] = self.skipped
        return out


@dataclass
class NmeaTables:
    """The two tables of a log: one row per epoch, one per satellite and epoch."""

    epochs: pd.DataFrame
    satellites: pd.DataFrame
    stats: ReadStats | None = None


def read_nmea(source: str | os.PathLike | BinaryIO, **options) -> NmeaTables:
    """Read a whole log into memory (for small logs and tests); see :func:`iter_nmea_tables`."""
    stats = options.pop("stats", None) or ReadStats()
    chunks = list(iter_nmea_tables(source, stats=stats, **options))
    if not chunks:
        return NmeaTables(epoch_frame(None), satellite_frame(None, None), stats)
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
) -> Iterator[NmeaTables]:
    """Yield the log's tables chunk by chunk (each chunk ≈ ``chunk_epochs`` epochs).

    ``date``: the UTC date of the first epoch, for logs without RMC/ZDA.
    ``block_bytes``: bytes read at a time (chunks are cut at block ends).
    ``stats`` (optional) is filled in as lines are read.
    ``engine``: ``"bulk"`` (the fast path, :mod:`tollcli.nmea.bulk_reader`) or
    ``"reference"`` (one line at a time; the bulk path is tested against it).
    """
    stats = stats if stats is not None else ReadStats()
    name = source_name(source)
    stats.source = name
    carry = DateCarry()
    if date is not None:
        carry.last_day = (date - _dt.date(1970, 1, 1)).days
    pending: list[dict[str, np.ndarray]] = []
    stream = open_binary(source)
    if engine == "bulk":
        try:
            yield from _bulk_chunks(stream, name, stats, strict, chunk_epochs, block_bytes, pending, carry)
        finally:
            if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
                stream.close()
        return
    if engine != "reference":
        raise ValueError(f"engine {engine!r}: 'bulk' or 'reference'")
    asm = EpochAssembler()
    try:
        for lines in iter_text_blocks(stream, name, block_bytes):
            _feed_lines(lines, asm, stats, strict, name)
            if asm.n_ready >= chunk_epochs:
                yield from _emit(asm.take(), pending, carry, stats, final=False)
        asm.finish()
        yield from _emit(asm.take(), pending, carry, stats, final=True)
    finally:
        if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
            stream.close()


def _bulk_chunks(stream, name, stats, strict, chunk_epochs, block_bytes, pending, carry) -> Iterator[NmeaTables]:
    from tollcli.nmea.bulk_reader import BulkReader, _merge

    bulk = BulkReader(stats, strict, name)
    ready: list[dict[str, np.ndarray]] = []
    n_ready = 0
    for block in iter_byte_blocks(stream, name, block_bytes):
        arrays = bulk.feed(block)
        if arrays is not None:
            ready.append(arrays)
            n_ready += arrays["epoch"].size
        if n_ready >= chunk_epochs:
            yield from _emit(_merge(ready), pending, carry, stats, final=False)
            ready, n_ready = [], 0
    arrays = bulk.finish()
    if arrays is not None:
        ready.append(arrays)
    yield from _emit(_merge(ready), pending, carry, stats, final=True)


HANDLED_TYPES = frozenset(EpochAssembler().handled_types())


def classify_line(line: str) -> tuple[str, str, str, list[str]]:
    """What one raw line is: ``(kind, why, address, fields)``.

    ``kind``: ``blank``, ``comment``, ``not_nmea``, ``no_checksum``, ``bad_checksum``
    (``why`` says what is wrong), ``unused`` (a valid sentence the reader does not
    use) or ``sentence`` (a valid sentence of a type the assembler reads; ``fields``
    are those after the address).
    """
    line = line.strip()
    if not line:
        return "blank", "", "", []
    if line[0] == "#":
        return "comment", "", "", []
    if line.startswith(ANDROID_PREFIX):
        line = line[len(ANDROID_PREFIX) :]
    star = line.rfind("*")
    end = star if star >= 0 else len(line)
    start = max(line.rfind("$", 0, end), line.rfind("!", 0, end))  # '!': encapsulated (AIS) sentences
    if start < 0:
        return "not_nmea", "not an NMEA sentence", "", []
    if star < 0:
        return "no_checksum", "no checksum (truncated sentence?)", "", []
    body = line[start + 1 : star]
    try:
        expected = int(line[star + 1 : star + 3], 16)
    except ValueError:
        return "no_checksum", "unreadable checksum", "", []
    got = checksum(body)
    if got != expected:
        return "bad_checksum", f"bad checksum (*{expected:02X} given, {got:02X} computed)", "", []
    fields = body.split(",")
    address = fields[0]
    if len(address) != 5 or address[0] == "P" or address[2:] not in HANDLED_TYPES:
        return "unused", "", address, []
    return "sentence", "", address, fields[1:]


def _feed_lines(lines: list[str], asm: EpochAssembler, stats: ReadStats, strict: bool, name: str) -> None:
    """Classify, verify and decode one block of lines, one line at a time (the reference path)."""
    line_no = stats.lines
    for line in lines:
        line_no += 1
        kind, why, address, fields = classify_line(line)
        if kind == "sentence":
            stats.sentences += 1
            try:
                asm.feed(address[:2], address[2:], fields, line_no)
            except (ValueError, IndexError, OverflowError) as exc:
                _problem(stats, "malformed", line_no, f"malformed {address}: {exc}", strict, name)
                continue
            stats.decoded += 1
        elif kind == "unused":
            stats.sentences += 1
            stats.unused += 1
            stats.unused_types[address] = stats.unused_types.get(address, 0) + 1
        elif kind == "blank":
            stats.blank += 1
        elif kind == "comment":
            stats.comments += 1
        else:
            _problem(stats, kind, line_no, why, strict, name)
    stats.lines = line_no


def _problem(stats: ReadStats, kind: str, line_no: int, why: str, strict: bool, name: str) -> None:
    if strict:
        raise DataError(f"{name}:{line_no}: {why}")
    setattr(stats, kind, getattr(stats, kind) + 1)
    if not stats.first_problem:
        stats.first_problem = f"line {line_no}: {why}"


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
    days = resolve_days(arrays["tod_s"], arrays["date_days"], carry)
    time_utc = to_time_utc_ms(days, arrays["tod_s"])
    epochs = epoch_frame(arrays, time_utc)
    sats = satellite_frame(arrays, time_utc)
    stats.epochs += len(epochs)
    stats.satellite_rows += len(sats)
    stats.undated_epochs += int((days < 0).sum())
    yield NmeaTables(epochs, sats, stats)


def check_partial(stats: ReadStats, max_bad: int | None) -> None:
    """Raise PartialError (exit 3) when more lines were skipped than ``--max-bad`` allows."""
    if max_bad is not None and stats.skipped > max_bad:
        raise PartialError(f"{stats.source}: {stats.skipped} lines skipped, more than --max-bad {max_bad} "
                           f"(first: {stats.first_problem}); outputs were written")  # fmt: skip


def check_usable(stats: ReadStats) -> None:
    """Raise DataError when a log gave nothing a toll processor can use."""
    if stats.lines == 0:
        raise DataError(f"{stats.source}: empty file")
    if stats.sentences == 0:
        hint = f"; first problem at {stats.first_problem}" if stats.first_problem else ""
        raise DataError(f"{stats.source}: no NMEA sentences in {stats.lines} lines (not an NMEA log?){hint}")
    if stats.epochs == 0:
        raise DataError(
            f"{stats.source}: {stats.sentences} NMEA sentences but no epoch: no GGA/RMC/GLL/GNS/ZDA gave a time of day"
        )
