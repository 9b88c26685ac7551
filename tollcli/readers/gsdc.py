"""The Google Smartphone Decimeter Challenge "derived" CSV, read and checked.

One row per satellite-signal and epoch (``millisSinceGpsEpoch``) with the
satellite's ECEF position, clock bias and modelled delays; positions and RAIM
measurements are made from it in :mod:`tollcli.gnss.gsdc_positions`.
"""

from __future__ import annotations

from collections.abc import Iterator

import pandas as pd

from tollcli.errors import DataError
from tollcli.readers.csv_numbers import checked_numbers, joined_blocks

ANDROID_CONSTELLATION = {1: "GPS", 2: "SBAS", 3: "GLONASS", 4: "QZSS", 5: "BeiDou", 6: "Galileo", 7: "NavIC"}
REQUIRED = ("millisSinceGpsEpoch", "constellationType", "svid", "signalType", "xSatPosM", "ySatPosM", "zSatPosM",
            "satClkBiasM", "rawPrM", "rawPrUncM", "isrbM", "ionoDelayM", "tropoDelayM")  # fmt: skip


#: the integer columns (the rest of :data:`REQUIRED` but ``signalType`` are floats)
INTEGERS = ("millisSinceGpsEpoch", "constellationType", "svid")


def read_gsdc_derived(path, strict: bool = False) -> pd.DataFrame:
    """The derived CSV with the columns the WLS needs, checked: its blocks (:func:`iter_gsdc_derived`) joined, a row
    whose number fields are not numbers skipped and counted (``attrs['skipped_lines']``, the first at
    ``attrs['first_skipped_line']``), or with ``strict`` an error naming its line."""
    return joined_blocks(list(iter_gsdc_derived(path, strict)))


#: rows of a derived CSV checked at a time by :func:`iter_gsdc_derived`
BLOCK_ROWS = 50_000


def iter_gsdc_derived(path, strict: bool = False, block_rows: int | None = None) -> Iterator[pd.DataFrame]:
    """The derived CSV :data:`BLOCK_ROWS` rows at a time, in file order, only the columns the WLS needs (the others
    would be a Python string per field), checked (:func:`~tollcli.readers.csv_numbers.checked_numbers`): each block's
    ``attrs['skipped_lines']`` its own malformed rows, ``line`` the file's line numbers. A file none of whose rows is
    usable is an error after its last block. Memory is a block's."""
    wanted = set(REQUIRED)
    floats = tuple(c for c in REQUIRED if c not in INTEGERS and c != "signalType")
    line, usable, first_bad = 2, 0, None
    try:
        reader = pd.read_csv(path, dtype=str, usecols=lambda c: c in wanted, chunksize=block_rows or BLOCK_ROWS)
        with reader:
            for table in reader:
                missing = [c for c in REQUIRED if c not in table.columns]
                if missing:
                    raise DataError(f"{path}: not a GSDC derived file, missing columns {', '.join(missing)}")
                checked = checked_numbers(table.reset_index(drop=True), path, floats, INTEGERS, strict, first_line=line)
                line += len(table)
                usable += len(checked)
                first_bad = first_bad or checked.attrs["first_skipped_line"]
                yield checked
    except (OSError, pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"{path}: not a readable CSV ({' '.join(str(exc).split())})") from None
    if not usable:
        raise DataError(f"{path}: no usable rows (the first bad one at line {first_bad})")
