"""What the direct RINEX observation readers (:mod:`~tollcli.readers.rinex2_obs`, :mod:`~tollcli.readers.rinex3_obs`)
share: a first pass's plan, the file's lines as georinex reads them, the rows of a block of records, and the signal
that a file is georinex's to read."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class ObservationPlan:
    """What a first pass over a RINEX observation file found: each system's observation types and the columns read
    (the candidate codes and their C/N0), the code each system's pseudorange is read from (None: none has a value),
    and the file's RINEX version (2 or 3: its records' layout)."""

    types: dict[str, list[str]]
    columns: dict[str, list[int]]
    codes: dict[str, str | None]
    version: int = 3


class Refused(Exception):
    """The file is one georinex should read (the readers' docstrings say when)."""


def first_pass(path: str, version: int, header_of, records_of, keep: list | None = None) -> ObservationPlan | None:
    """A first pass over a RINEX observation file of ``version`` (line by line: memory flat): its plan, or None where
    georinex should read it. ``header_of(lines)``: the version's header (types, columns, wanted, …) with ``lines`` left
    at the first record, None where georinex should read the file; ``records_of(lines, header)``: its records.
    ``keep``: a list that receives the records read (the whole file's, for a caller that reads it whole)."""
    try:
        with text_lines(path) as lines:
            header = header_of(lines)
            if header is None:
                return None
            seen_value = values_seen(records_of(lines, header), header[1], keep)
            for _ in lines:  # (what follows the records is not read, but must be ASCII text too)
                pass
    except (ValueError, IndexError, KeyError, OSError, UnicodeDecodeError, Refused):
        return None
    return plan_of(*header[:3], seen_value, version)


def file_records(path: str, header_of, records_of) -> Iterator[tuple[dt.datetime, list]]:
    """The records of a file whose first pass (:func:`first_pass`) made a plan, in file order."""
    with text_lines(path) as lines:
        yield from records_of(lines, header_of(lines))


def values_seen(records, columns: dict[str, list[int]], keep: list | None) -> dict[str, np.ndarray]:
    """A first pass over ``records`` (time, satellites' values of ``columns``): per system, which columns ever had a
    value; ``keep`` (a list, or None) receives the records."""
    seen_value = {s: np.zeros(len(columns[s]), bool) for s in columns}
    for record in records:
        if keep is not None:
            keep.append(record)
        for sv, values in record[1]:
            if sv[0] in seen_value:
                seen_value[sv[0]] |= np.isfinite(values)
    return seen_value


def plan_of(types: dict[str, list[str]], columns: dict[str, list[int]], wanted: dict[str, list[str]],
            seen_value: dict[str, np.ndarray], version: int) -> ObservationPlan | None:
    """The plan of a file whose first pass saw, per system, which of the ``columns`` read ever had a value
    (``seen_value``): each system's code the first of its candidates (``wanted``) with one; None where no system has
    a pseudorange (georinex then says so)."""
    codes = {}
    for system in columns:
        index = {types[system][i]: k for k, i in enumerate(columns[system])}
        codes[system] = next((c for c in wanted[system] if seen_value[system][index[c]]), None)
    return ObservationPlan(types, columns, codes, version) if any(codes.values()) else None


def text_lines(path: str):
    """The file's lines as georinex's text file gives them (universal newlines), ASCII only."""
    return open(path, encoding="ascii", newline=None)


def block_rows(block: list[tuple[dt.datetime, list]], plan: ObservationPlan) -> pd.DataFrame:
    """The rows of a block of records (time, satellites' values of the plan's columns), sorted by time and satellite:
    time (GPS time, ns), sv, pr_m, cn0_dbhz, code."""
    read = {system: ([], [], []) for system, code in plan.codes.items() if code is not None}  # epochs, satellites, values
    for k, (_time, sats) in enumerate(block):
        for sv, v in sats:
            if sv[0] in read:
                epochs, svs, values = read[sv[0]]
                epochs.append(k)
                svs.append(sv)
                values.append(v)
    frames = []
    for system, (epochs, svs, values) in read.items():
        code = plan.codes[system]
        table = np.array(values, float).reshape(len(epochs), len(plan.columns[system]))
        index = {plan.types[system][i]: k for k, i in enumerate(plan.columns[system])}
        snr = table[:, index["S" + code[1:]]] if "S" + code[1:] in index else np.full(len(epochs), np.nan)
        frames.append(pd.DataFrame({"epoch": np.asarray(epochs, np.int64), "sv": np.asarray(svs, dtype=object), "pr_m": table[:, index[code]],
                                    "cn0_dbhz": snr, "code": code}))  # fmt: skip
    out = pd.concat(frames, ignore_index=True)
    out = out[np.isfinite(out["pr_m"].to_numpy())]
    stamps = np.array([time for time, _ in block], dtype="datetime64[us]").astype("datetime64[ns]")
    out.insert(0, "time", stamps[out["epoch"].to_numpy()])
    return out.drop(columns="epoch").sort_values(["time", "sv"], kind="stable").reset_index(drop=True)
