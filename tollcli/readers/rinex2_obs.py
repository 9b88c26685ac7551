"""RINEX 2 observation files read directly: the rows :func:`tollcli.readers.rinex.observations` makes of georinex's
dataset, the same rows, without building the dataset (as :mod:`tollcli.readers.rinex3_obs` reads RINEX 3).

georinex reads a RINEX 2 file once per system and merges the systems' datasets; its arrays are the whole file's
(epochs × 36 satellites × observation types), so its memory grows with the file. A RINEX 2.11 record is fixed-width
text: an epoch line ``␣yy␣mm␣dd␣hh␣mm␣ss.sssssss␣␣f␣nn`` naming up to 12 satellites (``G05R12…``; continuation
lines of 12 more), then per satellite the values of the header's ``# / TYPES OF OBSERV`` in 16 columns each (a value
in 14, loss of lock and signal strength in one each), five to an 80-column line.

This reader takes those lines the way georinex does: every line after the header is tried as an epoch line and passed
over where it is not one (a time that does not parse, an event flag 2–4: ``georinex.obs2._timeobs``); a satellite's
lines are cut at 80 columns and padded to them; a satellite named with a blank system letter is GPS; the times are
kept to the millisecond where georinex reads them first (a file whose first satellite's lines are all shorter than 79
columns). It gives the file back to georinex (None) wherever the two could differ or georinex would refuse it: not
RINEX 2 observations, not plain ASCII text, a first line longer than 80 columns, a file system other than GPS,
GLONASS, Galileo, BeiDou or mixed (georinex reads nothing of a blank one), a mixed file without TIME OF FIRST OBS (its
time system), observation types not as many as said or one twice, an event flag 5 or 6, an epoch line cut short or a
satellite list that does not read, a satellite number outside 1–36, an epoch time twice, a satellite twice in an
epoch, a value that is not a number in a satellite of a system read, or no pseudorange at all. Tested row for row
against georinex on a real receiver's log turned into RINEX 2.11 by RTKLIB's ``convbin``, on synthetic files and on
1 150 randomly damaged copies (every one read alike or left to georinex). One difference is kept on purpose: georinex
(its default ``fast`` reading) guesses the number of epochs from the file's size and the first epoch and stops with an
IndexError when a file has more; this reader reads such a file.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from math import ceil

import numpy as np

from tollcli.readers.rinex import CODES
from tollcli.readers.rinex_records import ObservationPlan, Refused, first_pass

#: the systems read (georinex's ``use``)
SYSTEMS = tuple(CODES)
#: georinex's satellites per system (``Nsvsys``): a number above it stops georinex
MAX_SVID = 36


def rinex2_plan(path: str, keep: list | None = None) -> ObservationPlan | None:
    """A first pass over a RINEX 2 observation file (:func:`~tollcli.readers.rinex_records.first_pass`): its plan, or
    None where georinex should read it."""
    return first_pass(path, 2, header_of, records_of, keep)


def records_of(lines, header) -> Iterator[tuple[dt.datetime, list]]:
    """The records (time, satellites' values of the header's columns) of the lines after the header (:func:`header_of`)."""
    types, columns, _wanted, per_satellite = header
    return _records(lines, columns, len(next(iter(types.values()))), per_satellite)


def header_of(lines) -> tuple[dict[str, list[str]], dict[str, list[int]], dict[str, list[str]], int] | None:
    """The observation types of each system read (the header's one list, for each), the columns read of each, its
    candidate codes (in CODES' order) and the lines a satellite's values take; ``lines`` left at the first record.
    None where georinex should read the file."""
    first = next(lines, "")
    if "END OF HEADER" in first or first[60:80] != "RINEX VERSION / TYPE" or len(first.rstrip("\n")) > 80:
        return None
    if first[20:21] != "O" or int(float(first[:9])) != 2:  # (a version that does not read: ValueError, as georinex's)
        return None
    file_system = first[40:41]
    systems = [s for s in SYSTEMS if file_system in (s, "M")]
    if not systems:
        return None
    names: list[str] = []
    declared = None
    ended = first_obs = False
    for line in lines:
        if "END OF HEADER" in line:
            ended = True
            break
        first_obs |= line[60:80].strip() == "TIME OF FIRST OBS"
        if "# / TYPES OF OBSERV" in line[60:80]:
            if declared is None:
                declared = int(line[:6])
            names += line[6:60].split()
    if not ended or declared is None or declared != len(names) or declared == 0 or len(set(names)) != len(names):
        return None  # (a type twice: georinex keeps its last column)
    if file_system == "M" and not first_obs:
        return None  # (a mixed file's time system is in TIME OF FIRST OBS: georinex stops without it)
    types = {s: names for s in systems}
    wanted = {s: [c for c in CODES[s] if c in names] for s in systems}
    columns = {s: sorted({names.index(c) for c in wanted[s]} | {names.index("S" + c[1:]) for c in wanted[s] if "S" + c[1:] in names})
               for s in systems}  # fmt: skip
    return types, columns, wanted, ceil(declared / 5)


def _records(lines, columns: dict[str, list[int]], n_types: int, per_satellite: int) -> Iterator[tuple[dt.datetime, list]]:
    """Each epoch's time and its satellites' values of ``columns`` (the systems read), as georinex reads the records
    (see the module). Raises Refused where georinex should read the file."""
    seen_times: set[dt.datetime] = set()
    to_ms = None  # whether georinex keeps the times to the millisecond only (:func:`_to_the_millisecond`)
    for line in lines:
        try:
            time = _epoch_time(line)
        except ValueError:  # not an epoch line: georinex passes over it
            continue
        if len(line) < 32:
            raise Refused
        n_sats = int(line[29:32])
        svs = _satellites(line, min(12, n_sats))
        for _ in range((n_sats - 1) // 12):
            svs += _satellites(next(lines, ""), min(12, n_sats - len(svs)))
        if len(svs) != n_sats or len(set(svs)) != n_sats:
            raise Refused
        sats = []
        for sv in svs:
            sat_lines = [next(lines, "") for _ in range(per_satellite)]  # (georinex: past the end, blank)
            if to_ms is None:
                to_ms = _to_the_millisecond(sat_lines)
            raw = "".join(f"{text[:80]:80s}" for text in sat_lines)
            if sv[0] not in columns:
                continue
            values = [_value(raw[16 * k : 16 * k + 14]) for k in range(n_types)]  # (every one read: a bad one refuses)
            sats.append((sv, np.array([values[i] for i in columns[sv[0]]], float)))
        if to_ms is None:  # (an epoch of no satellite first: georinex would size its arrays from the next epoch's lines)
            raise Refused
        if to_ms:
            time = time.replace(microsecond=time.microsecond // 1000 * 1000)
        if time in seen_times:
            raise Refused
        seen_times.add(time)
        yield time, sats


def _to_the_millisecond(first_satellite: list[str]) -> bool:
    """Whether georinex keeps this file's epoch times to the millisecond only: it reads the times first, as
    ``datetime64[ms]``, unless the first epoch's first satellite has a line of 79 columns or more (then it guesses the
    epochs from the file's size, keeping the times to the microsecond: ``georinex.obs2._fast_alloc``)."""
    return max(len(text) for text in first_satellite) < 79


def _satellites(line: str, n: int) -> list[str]:
    """``n`` satellites of an epoch line (or its continuation) as georinex names them (``G05``; a blank system GPS)."""
    out = []
    for i in range(n):
        sv = line[32 + 3 * i : 35 + 3 * i]
        if len(sv) != 3:
            raise Refused
        number = int(sv[1:])  # (ValueError: not a satellite)
        if not 1 <= number <= MAX_SVID:
            raise Refused
        out.append(f"{'G' if sv[0] == ' ' else sv[0]}{number:02d}")
    return out


def _epoch_time(line: str) -> dt.datetime:
    """An epoch line's time as georinex reads it (``_timeobs``: a two-digit year, 1980–2079; the seconds' fraction
    truncated to the microsecond, 0 where it does not read); ValueError where it is no epoch line (georinex passes
    over it), Refused where georinex would stop or read it differently (event flags 5 and 6)."""
    year = int(line[1:3])
    year += 2000 if year < 80 else 1900
    try:
        usec = int(float(line[16:26]) % 1 * 1000000)
    except ValueError:
        usec = 0
    time = dt.datetime(year=year, month=int(line[4:6]), day=int(line[7:9]), hour=int(line[10:12]), minute=int(line[13:15]),
                       second=int(line[16:18]), microsecond=usec)  # fmt: skip
    if len(line) < 29:
        raise Refused  # (georinex stops: IndexError)
    flag = int(line[28])
    if flag in (5, 6):  # an external event, cycle slips: georinex reads them as epochs of satellites
        raise Refused
    if flag not in (0, 1):
        raise ValueError(f"epoch flag {flag}")
    return time


def _value(field: str) -> float:
    """A 14-column value: NaN where blank; ValueError where not a number (georinex then stops: Refused)."""
    if not field.strip():
        return np.nan
    try:
        return float(field)
    except ValueError:
        raise Refused from None

