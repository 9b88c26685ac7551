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
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.readers.csv_numbers import checked_numbers

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
    """The ``Raw`` records of a file, and what was skipped."""

    raw: pd.DataFrame
    n_malformed: int
    first_malformed_line: int | None  # 1-based line number of the first skipped record


def read_gnsslogger(path: str, strict: bool = False) -> RawRead:
    """The ``Raw`` records of a GnssLogger text file as a table (columns named by the file's own header)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a log file") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot open ({exc.strerror})") from None
    lines = data.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n").split("\n")
    header = next((ln[2:].split(",") for ln in lines if ln.startswith("# Raw,")), None)
    if header is None:
        raise DataError(f"{path}: not a GnssLogger file (no '# Raw,' header line)")
    missing = [c for c in RAW_REQUIRED if c not in header]
    if missing:
        raise DataError(f"{path}: the GnssLogger Raw header lacks {', '.join(missing)}")
    numbers = np.flatnonzero(np.char.startswith(np.array(lines, dtype=object).astype(str), "Raw,")) if lines else np.zeros(0, int)
    raw_lines = [lines[i] for i in numbers.tolist()]
    counts = np.array([ln.count(",") + 1 for ln in raw_lines], dtype=np.int64)
    bad = counts != len(header)
    first_bad = int(numbers[bad][0]) + 1 if bad.any() else None
    if strict and first_bad is not None:
        raise DataError(f"{path}:{first_bad}: a Raw record with {counts[bad][0]} fields, the header has {len(header)}")
    good = [ln for ln, b in zip(raw_lines, bad.tolist()) if not b]
    if not good:
        raise DataError(f"{path}: no usable Raw records (GnssLogger was not recording raw measurements)")
    try:
        raw = pd.read_csv(io.StringIO("\n".join(good)), header=None, names=header, dtype=str, low_memory=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: unreadable Raw records ({' '.join(str(exc).split())})") from None
    lines_of = numbers[~bad] + 1
    exact = _exact_columns(raw)
    raw = checked_numbers(raw, path, tuple(c for c in RAW_REQUIRED if c not in (*RAW_INTEGERS, *exact)), RAW_INTEGERS, strict,
                          exact=exact)  # fmt: skip
    raw["line"] = lines_of[raw["line"].to_numpy() - 2]  # checked_numbers counted rows from 2: the file's own lines
    n_bad = int(bad.sum()) + raw.attrs["skipped_lines"]
    raw.attrs["skipped_lines"] = 0  # counted in n_malformed
    if raw.empty:
        raise DataError(f"{path}: no usable Raw records")
    return RawRead(_exact(raw), n_bad, first_bad if first_bad is not None else None)


def read_device_gnss(path: str, strict: bool = False) -> pd.DataFrame:
    """A GSDC 2022/2023 ``device_gnss.csv`` (``Raw`` fields + Google's satellite columns), checked: a row whose
    number fields are not numbers is skipped and counted (``attrs['skipped_lines']``), or with ``strict`` an error."""
    try:
        table = pd.read_csv(path, dtype=str, low_memory=False)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"{path}: not a readable CSV ({' '.join(str(exc).split())})") from None
    missing = [c for c in RAW_REQUIRED if c not in table.columns]
    if missing:
        raise DataError(f"{path}: not a GSDC device_gnss file, missing columns {', '.join(missing)}")
    exact = _exact_columns(table)
    floats = tuple(c for c in (*RAW_REQUIRED, *DEVICE_GNSS_SATELLITE) if c in table.columns and c not in (*RAW_INTEGERS, *exact))
    table = checked_numbers(table, path, floats, RAW_INTEGERS, strict, exact=exact)
    if table.empty:
        raise DataError(f"{path}: no usable rows (the first bad one at line {table.attrs['first_skipped_line']})")
    return _exact(table)


def _exact_columns(raw: pd.DataFrame) -> tuple[str, ...]:
    """The nanosecond counts the table has (read digit for digit as ``Int64``)."""
    return tuple(c for c, dtype in EXACT_DTYPES.items() if dtype == "Int64" and c in raw.columns)


def _exact(raw: pd.DataFrame) -> pd.DataFrame:
    """The text columns as strings (the nanosecond counts are already exact integers)."""
    for name, dtype in EXACT_DTYPES.items():
        if name in raw.columns and dtype == "string":
            raw[name] = raw[name].astype(dtype)
    return raw
