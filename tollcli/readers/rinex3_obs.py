"""RINEX 3 observation files read directly: the rows :func:`tollcli.readers.rinex.observations` makes of georinex's
dataset, the same rows, without building the dataset.

georinex merges an xarray dataset per epoch into the file's, a cost that grows with the file: 52 s for an hour at
1 Hz (15 satellites, 2 MB), minutes for a day. A RINEX 3 observation record is fixed-width text (RINEX 3.05, A13):
an epoch line ``> yyyy mm dd hh mm ss.sssssss  f nn`` and a line per satellite, ``Snn`` and then 16 columns per
observation type of its system (``SYS / # / OBS TYPES``: a value in 14, loss of lock and signal strength in one each).
This reader takes from each satellite line only the columns the pseudorange needs — the candidate codes of its system
(:data:`tollcli.readers.rinex.CODES`) and their C/N0 — and chooses the code per system as ``observations`` does (the
first candidate with a value anywhere in the file).

It reads what georinex reads the way georinex reads it (its epoch time, satellite count and value fields, a time
line it cannot read passed over, the records ending at the first line that is not an epoch's), and gives the file
back to georinex (None) wherever the two could differ or georinex would refuse it: not RINEX 3 observations, not
plain ASCII text, no time system (a mixed file without TIME OF FIRST OBS), a system list without GPS, Galileo,
GLONASS or BeiDou, an epoch time twice, a satellite twice in an epoch, a satellite line cut short of its data or
holding ``#``, a value that is not a number, or no pseudorange at all. Tested row for row against georinex on
synthetic and real files, and on 460 randomly damaged copies of a real one (every one read alike or left to georinex).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator

import numpy as np

from tollcli.readers.rinex import CODES
from tollcli.readers.rinex_records import ObservationPlan, Refused, first_pass

#: the systems read (georinex's ``use``)
SYSTEMS = tuple(CODES)


def rinex3_plan(path: str, keep: list | None = None) -> ObservationPlan | None:
    """A first pass over a RINEX 3 observation file (:func:`~tollcli.readers.rinex_records.first_pass`): its plan, or
    None where georinex should read it."""
    return first_pass(path, 3, header_of, records_of, keep)


def records_of(lines, header) -> Iterator[tuple[dt.datetime, list]]:
    """The records (time, satellites' values of the header's columns) of the lines after the header (:func:`header_of`)."""
    return _records(lines, header[1])


def header_of(lines) -> tuple[dict[str, list[str]], dict[str, list[int]], dict[str, list[str]]] | None:
    """The header's observation types, the columns read of each system and its candidate codes (in CODES' order);
    ``lines`` left at the first record. None where georinex should read the file."""
    header = []
    for line in lines:
        header.append(line)
        if "END OF HEADER" in line:
            break
    found = _header(header)
    if found is None:
        return None
    types, _at = found
    systems = [s for s in SYSTEMS if s in types]
    if not systems:
        return None
    wanted = {s: [c for c in CODES[s] if c in types[s]] for s in systems}
    columns = {s: sorted({types[s].index(c) for c in wanted[s]} | {types[s].index("S" + c[1:]) for c in wanted[s] if "S" + c[1:] in types[s]})
               for s in systems}  # fmt: skip
    return types, columns, wanted


def _records(lines, columns: dict[str, list[int]]) -> Iterator[tuple[dt.datetime, list[tuple[str, np.ndarray]]]]:
    """Each epoch's time and its satellites' values of ``columns`` (the systems read), as georinex reads the records:
    a time it cannot read passed over (and the lines after it end the records), the records ending at the first line
    that is not an epoch's. Raises Refused where georinex should read the file."""
    seen_times: set[dt.datetime] = set()
    for line in lines:
        if not line.startswith(">"):
            return
        try:
            time = _epoch_time(line)
        except ValueError:  # georinex passes over a time it cannot read (and the lines after it end the records)
            continue
        n_sats = int(line[33:35])
        if time in seen_times:
            raise Refused
        seen_times.add(time)
        seen, sats = set(), []
        for _ in range(n_sats):
            sat_line = next(lines, None)
            if sat_line is None:  # (the file ends inside the epoch)
                raise Refused
            sv, data = sat_line[:3], sat_line[3:]
            if not data.strip("\r\n") or "#" in data or sv in seen:
                raise Refused
            seen.add(sv)
            if sv[0] in columns:
                sats.append((sv.replace(" ", "0"), np.array([_value(data[16 * i : 16 * i + 14]) for i in columns[sv[0]]], float)))
        yield time, sats


def _header(lines: list[str]) -> tuple[dict[str, list[str]], int] | None:
    """The observation types of each system (``SYS / # / OBS TYPES``) and the first record line; None where the file
    is not RINEX 3 observations or has no time system for georinex (its system letter, or a mixed file's TIME OF
    FIRST OBS)."""
    if not lines or "RINEX VERSION / TYPE" not in lines[0][60:80] or lines[0][20:21] != "O" or not lines[0][:9].strip().startswith("3"):
        return None
    float(lines[0][:9])  # (a version that does not read: ValueError, as georinex's)
    types: dict[str, list[str]] = {}
    labels = set()
    at = 1
    while at < len(lines) and "END OF HEADER" not in lines[at]:
        line = lines[at]
        at += 1
        labels.add(line[60:80].strip())
        if "SYS / # / OBS TYPES" in line[60:80]:
            system, count, names = line[0], int(line[3:6]), line[6:60].split()
            for _ in range((count - 1) // 13):  # continuation lines of 13 types each (RINEX 3.03, A6)
                if "SYS / # / OBS TYPES" not in lines[at][60:]:
                    raise ValueError("a continuation line missing")
                names += lines[at][6:60].split()
                at += 1
            if len(names) != count:
                raise ValueError("not as many types as said")
            types[system] = names
    file_system = lines[0][40:41]
    if file_system not in ("G", "R", "E", "J", "C", "I", "M") or (file_system == "M" and "TIME OF FIRST OBS" not in labels):
        return None
    return types, at + 1


def _epoch_time(line: str) -> dt.datetime:
    """An epoch line's time as georinex reads it (its seconds' fraction truncated to the microsecond)."""
    if not line.startswith("> "):
        raise ValueError("not an epoch line")
    return dt.datetime(int(line[2:6]), int(line[7:9]), int(line[10:12]), hour=int(line[13:15]), minute=int(line[16:18]),
                       second=int(line[19:21]), microsecond=int(float(line[19:29]) % 1 * 1000000))  # fmt: skip


def _value(field: str) -> float:
    """A 14-column value: NaN where blank; ValueError where not a number (georinex then reads the file)."""
    return float(field) if field.strip() else np.nan
