"""Android GnssLogger text files (``Raw`` records) and the GSDC 2022/2023 ``device_gnss.csv``, read into tables.

GnssLogger writes one record per line, each starting with its kind (``Raw``, ``Fix``, ``Status``,
``UncalAccel`` …); the column names of each kind are given once in a comment (``# Raw,utcTimeMillis,…``)
and change between app versions, so the header of the file is what is read, not a fixed list. Only the
``Raw`` records (one per satellite-signal and epoch: Android's ``GnssMeasurement`` and ``GnssClock``
fields) are kept here; a ``Raw`` line whose field count differs from its header is skipped and counted
(``--strict``: an error naming the line).

The GSDC 2022/2023 ``device_gnss.csv`` is the same ``Raw`` fields as a CSV, plus Google's derived
columns (satellite positions, clocks, delays). Pseudoranges are built from either in
:mod:`tollcli.gnss.android_raw`.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.readers.csv_numbers import checked_numbers, joined_blocks

#: the ``Raw`` fields a pseudorange needs (Android GnssClock + GnssMeasurement names)
RAW_REQUIRED = ("TimeNanos", "FullBiasNanos", "BiasNanos", "TimeOffsetNanos", "ReceivedSvTimeNanos", "State",
                "Svid", "ConstellationType", "Cn0DbHz", "PseudorangeRateMetersPerSecond")  # fmt: skip
#: the derived columns of a GSDC 2022/2023 ``device_gnss.csv`` (satellite states at transmission time)
DEVICE_GNSS_SATELLITE = ("SvPositionXEcefMeters", "SvPositionYEcefMeters", "SvPositionZEcefMeters",
                         "SvVelocityXEcefMetersPerSecond", "SvVelocityYEcefMetersPerSecond",
                         "SvVelocityZEcefMetersPerSecond", "SvClockBiasMeters", "SvClockDriftMetersPerSecond")  # fmt: skip

#: nanosecond counts since 1980 need all 64 bits (a float64 column would round them to ~100 ns)
EXACT_DTYPES = {"FullBiasNanos": "Int64", "TimeNanos": "Int64", "ReceivedSvTimeNanos": "Int64", "CodeType": "string"}
#: the ``Raw`` fields that must be integers in every row (a missing one makes the row malformed)
RAW_INTEGERS = ("State", "Svid", "ConstellationType")


@dataclass
class RawRead:
    """The ``Raw`` records of a file (or of a block of it: None where the block has none), and what was skipped."""

    raw: pd.DataFrame | None
    n_malformed: int
    first_malformed_line: int | None  # 1-based line number of the first skipped record


def read_gnsslogger(path: str, strict: bool = False) -> RawRead:
    """The ``Raw`` records of a GnssLogger text file as a table (columns named by the file's own header): its blocks
    (:func:`iter_gnsslogger`) joined."""
    parts = list(iter_gnsslogger(path, strict))
    raw = pd.concat([p.raw for p in parts if p.raw is not None], ignore_index=True)
    raw.attrs["skipped_lines"] = 0  # counted in n_malformed
    return RawRead(raw, sum(p.n_malformed for p in parts), next((p.first_malformed_line for p in parts if p.first_malformed_line), None))


#: bytes of a GnssLogger file read at a time by :func:`iter_gnsslogger` (whole lines: a block ends at a line's end)
BLOCK_BYTES = 8 << 20


def iter_gnsslogger(path: str, strict: bool = False, block_bytes: int | None = None) -> Iterator[RawRead]:
    """The ``Raw`` records of a GnssLogger text file, :data:`BLOCK_BYTES` of the file at a time, in file order: each
    block's records (columns named by the file's header line ``# Raw,…``, wherever it is before them), its skipped
    lines and the first of them (the file's line numbers). A file without the header, or none of whose records is
    usable, is an error (after its last block). Memory is a block's."""
    header: list[str] | None = None
    waiting: list[tuple[list[str], int]] = []  # blocks read before the header was found (normally none)
    line, any_good, any_usable = 1, False, False
    for lines in _line_blocks(path, block_bytes or BLOCK_BYTES):
        if header is None:
            header = next((ln[2:].split(",") for ln in lines if ln.startswith("# Raw,")), None)
            if header is not None:
                missing = [c for c in RAW_REQUIRED if c not in header]
                if missing:
                    raise DataError(f"{path}: the GnssLogger Raw header lacks {', '.join(missing)}")
        waiting.append((lines, line))
        line += len(lines)
        if header is None:
            continue
        for held, first_line in waiting:
            read, good = _raw_records(path, held, first_line, header, strict)
            any_good |= good
            any_usable |= read.raw is not None and len(read.raw) > 0
            if read.raw is not None or read.n_malformed:
                yield read
        waiting = []
    if header is None:
        raise DataError(f"{path}: not a GnssLogger file (no '# Raw,' header line)")
    if not any_good:
        raise DataError(f"{path}: no usable Raw records (GnssLogger was not recording raw measurements)")
    if not any_usable:
        raise DataError(f"{path}: no usable Raw records")


def _line_blocks(path: str, block_bytes: int) -> Iterator[list[str]]:
    """The file's lines (latin-1; CR LF, CR and LF all end a line), about ``block_bytes`` at a time, whole lines."""
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a log file") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot open ({exc.strerror})") from None
    with fh:
        rest = b""
        while True:
            data = fh.read(block_bytes)
            if not data:
                break
            data = rest + data
            cut = data.rfind(b"\n") + 1  # (a CR LF is never split: the block ends after its LF)
            if cut == 0:  # no line end yet (or a file of CR ends only): read on
                rest = data
                continue
            rest = data[cut:]
            yield _split(data[:cut])[:-1]  # (the empty text after the block's last line end is no line)
        if rest:
            yield _split(rest)


def _split(data: bytes) -> list[str]:
    return data.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _raw_records(path: str, lines: list[str], first_line: int, header: list[str], strict: bool) -> tuple[RawRead, bool]:
    """The ``Raw`` records of ``lines`` (the first is line ``first_line`` of the file; ``raw`` None where no record
    has the header's fields), and whether any has."""
    numbers = np.flatnonzero(np.char.startswith(np.array(lines, dtype=object).astype(str), "Raw,")) if lines else np.zeros(0, int)
    raw_lines = [lines[i] for i in numbers.tolist()]
    counts = np.array([ln.count(",") + 1 for ln in raw_lines], dtype=np.int64)
    bad = counts != len(header)
    first_bad = int(numbers[bad][0]) + first_line if bad.any() else None
    if strict and first_bad is not None:
        raise DataError(f"{path}:{first_bad}: a Raw record with {counts[bad][0]} fields, the header has {len(header)}")
    good = [ln for ln, b in zip(raw_lines, bad.tolist()) if not b]
    if not good:
        return RawRead(None, int(bad.sum()), first_bad), False
    try:
        raw = pd.read_csv(io.StringIO("\n".join(good)), header=None, names=header, dtype=str, low_memory=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: unreadable Raw records ({' '.join(str(exc).split())})") from None
    lines_of = numbers[~bad] + first_line
    exact = _exact_columns(raw)
    raw = checked_numbers(raw, path, tuple(c for c in RAW_REQUIRED if c not in (*RAW_INTEGERS, *exact)), RAW_INTEGERS, strict,
                          exact=exact, line_numbers=lines_of)  # fmt: skip
    n_bad = int(bad.sum()) + raw.attrs["skipped_lines"]
    raw.attrs["skipped_lines"] = 0  # counted in n_malformed
    return RawRead(_exact(raw), n_bad, first_bad), True


def read_device_gnss(path: str, strict: bool = False) -> pd.DataFrame:
    """A GSDC 2022/2023 ``device_gnss.csv`` (``Raw`` fields + Google's satellite columns), checked: a row whose
    number fields are not numbers is skipped and counted (``attrs['skipped_lines']``), or with ``strict`` an error.
    Its blocks (:func:`iter_device_gnss`) joined."""
    return joined_blocks(list(iter_device_gnss(path, strict)))


#: rows of a ``device_gnss.csv`` read at a time by :func:`iter_device_gnss`
BLOCK_ROWS = 50_000


def iter_device_gnss(path: str, strict: bool = False, block_rows: int | None = None) -> Iterator[pd.DataFrame]:
    """A ``device_gnss.csv`` :data:`BLOCK_ROWS` rows at a time, in file order, checked as :func:`read_device_gnss`
    says: each block's ``attrs['skipped_lines']`` its own malformed rows, ``line`` the file's line numbers. A file
    none of whose rows is usable is an error after its last block. Memory is a block's."""
    line, usable, first_bad, seen = 2, 0, None, False
    try:
        reader = pd.read_csv(path, dtype=str, chunksize=block_rows or BLOCK_ROWS)
        with reader:
            for table in reader:
                seen = True
                missing = [c for c in RAW_REQUIRED if c not in table.columns]
                if missing:
                    raise DataError(f"{path}: not a GSDC device_gnss file, missing columns {', '.join(missing)}")
                exact = _exact_columns(table)
                floats = tuple(c for c in (*RAW_REQUIRED, *DEVICE_GNSS_SATELLITE) if c in table.columns and c not in (*RAW_INTEGERS, *exact))
                checked = checked_numbers(table.reset_index(drop=True), path, floats, RAW_INTEGERS, strict, exact=exact, first_line=line)
                line += len(table)
                usable += len(checked)
                first_bad = first_bad or checked.attrs["first_skipped_line"]
                yield _exact(checked)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"{path}: not a readable CSV ({' '.join(str(exc).split())})") from None
    if not seen:  # a header and no row: its columns still say whether it is one
        header = pd.read_csv(path, dtype=str, nrows=0)
        missing = [c for c in RAW_REQUIRED if c not in header.columns]
        if missing:
            raise DataError(f"{path}: not a GSDC device_gnss file, missing columns {', '.join(missing)}")
    if not usable:
        raise DataError(f"{path}: no usable rows (the first bad one at line {first_bad})")


def _exact_columns(raw: pd.DataFrame) -> tuple[str, ...]:
    """The nanosecond counts the table has (read digit for digit as ``Int64``)."""
    return tuple(c for c, dtype in EXACT_DTYPES.items() if dtype == "Int64" and c in raw.columns)


def _exact(raw: pd.DataFrame) -> pd.DataFrame:
    """The text columns as strings (the nanosecond counts are already exact integers)."""
    for name, dtype in EXACT_DTYPES.items():
        if name in raw.columns and dtype == "string":
            raw[name] = raw[name].astype(dtype)
    return raw
