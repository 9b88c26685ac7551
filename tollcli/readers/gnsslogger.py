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

#: the ``Raw`` fields a pseudorange needs (Android GnssClock + GnssMeasurement names)
RAW_REQUIRED = ("TimeNanos", "FullBiasNanos", "BiasNanos", "TimeOffsetNanos", "ReceivedSvTimeNanos", "State",
                "Svid", "ConstellationType", "Cn0DbHz", "PseudorangeRateMetersPerSecond")  # fmt: skip
#: the derived columns of a GSDC 2022/2023 ``device_gnss.csv`` (satellite states at transmission time)
DEVICE_GNSS_SATELLITE = ("SvPositionXEcefMeters", "SvPositionYEcefMeters", "SvPositionZEcefMeters",
                         "SvVelocityXEcefMetersPerSecond", "SvVelocityYEcefMetersPerSecond",
                         "SvVelocityZEcefMetersPerSecond", "SvClockBiasMeters", "SvClockDriftMetersPerSecond")  # fmt: skip

#: nanosecond counts since 1980 need all 64 bits (a float64 column would round them to ~100 ns)
EXACT_DTYPES = {"FullBiasNanos": "Int64", "TimeNanos": "Int64", "ReceivedSvTimeNanos": "Int64", "CodeType": "string"}


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
        raw = pd.read_csv(io.StringIO("\n".join(good)), header=None, names=header, dtype=EXACT_DTYPES,
                          low_memory=False)  # fmt: skip
    except (ValueError, pd.errors.ParserError) as exc:
        raise DataError(f"{path}: unreadable Raw records ({exc})") from None
    raw = _numeric(raw, path)
    raw["line"] = numbers[~bad] + 1
    return RawRead(raw, int(bad.sum()), first_bad)


def read_device_gnss(path: str) -> pd.DataFrame:
    """A GSDC 2022/2023 ``device_gnss.csv`` (``Raw`` fields + Google's satellite columns), checked."""
    try:
        table = pd.read_csv(path, dtype={**EXACT_DTYPES, "SignalType": "string"}, low_memory=False)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"{path}: not a readable CSV ({exc})") from None
    missing = [c for c in RAW_REQUIRED if c not in table.columns]
    if missing:
        raise DataError(f"{path}: not a GSDC device_gnss file, missing columns {', '.join(missing)}")
    table = _numeric(table, path)
    table["line"] = np.arange(len(table)) + 2
    return table


def _numeric(raw: pd.DataFrame, path: str) -> pd.DataFrame:
    """The fields a pseudorange needs as numbers (an empty field: NaN; text where a number belongs: an error)."""
    for name in RAW_REQUIRED:
        if name in EXACT_DTYPES:
            continue
        col = pd.to_numeric(raw[name], errors="coerce")
        bad = col.isna() & raw[name].notna()
        if bad.any():
            raise DataError(f"{path}: Raw field {name} is not a number ({raw[name][bad].iloc[0]!r})")
        raw[name] = col
    return raw
