"""Full UTC dates for epochs whose sentences carry only a time of day.

Only RMC (``ddmmyy``) and ZDA carry a date. Every other epoch takes the date of
the nearest dated epoch, counting midnight rollovers in between: a rollover is a
time of day that drops by more than 12 h from one epoch to the next. Epochs
before the first dated one take it backwards the same way. Vectorized over the
epochs of a chunk; :class:`DateCarry` holds what the next chunk needs.

A continuous trip keeps one calendar: while the time of day runs on (steps of 0 to
``MAX_CONTINUOUS_STEP_S``, a midnight rollover included) the date is the one the trip's
first dated epoch gave, counted on through midnights. A later RMC/ZDA date that disagrees
(a receiver's date jump, a GPS week-number rollover of 1024 weeks) does not move the
epochs: it is kept as ``date_jump_days`` (given minus carried date) for the findings. After
a gap in the time of day (the receiver was off), the next given date is taken as it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HALF_DAY_S = 43_200.0
DAY_S = 86_400.0
MS_PER_DAY = 86_400_000
#: the longest step of the time of day, s, that still continues a trip (longer: the receiver was off)
MAX_CONTINUOUS_STEP_S = 600.0


@dataclass
class DateCarry:
    """State from the previous chunk: its last time of day and date."""

    last_tod_s: float = float("nan")
    last_day: int = -1  # days since 1970-01-01, -1 unknown
    #: the date ``--date`` gave (days since 1970-01-01), until the log's own first date has been compared with it
    given_day: int = -1


def resolve_days(tod_s: np.ndarray, date_days: np.ndarray, carry: DateCarry) -> tuple[np.ndarray, np.ndarray]:
    """Days since 1970-01-01 per epoch (-1 where no date can be known yet), and each epoch's date jump.

    ``tod_s``: time of day per epoch, seconds; ``date_days``: the date an epoch's
    own RMC/ZDA gave, -1 where none. Returns (days, ``date_jump_days``): the jump is the
    given date minus the trip's date where they differ inside a continuous trip, NaN elsewhere.
    ``carry`` is updated for the next chunk.
    """
    n = tod_s.size
    if n == 0:
        return np.empty(0, dtype=np.int64), np.empty(0)
    prev = np.concatenate(([carry.last_tod_s], tod_s[:-1]))
    with np.errstate(invalid="ignore"):
        step = tod_s - prev
        rollover = step < -HALF_DAY_S
        step = np.where(rollover, step + DAY_S, step)
        continuous = (step >= 0) & (step <= MAX_CONTINUOUS_STEP_S)
    if carry.last_day < 0:
        continuous[0] = False
    rolls = np.cumsum(rollover).astype(np.int64)
    given = date_days >= 0
    # a trip (a run of continuous epochs) takes its first given date; trip 0 continues the carried one
    trip = np.cumsum(~continuous)
    rows = np.flatnonzero(given)
    first_of_trip = rows[np.r_[True, trip[rows][1:] != trip[rows][:-1]]] if rows.size else rows
    anchor = np.zeros(n, dtype=bool)
    anchor[first_of_trip] = True
    anchor &= trip > 0
    base = np.where(anchor, date_days - rolls, -1)
    # forward fill the base (date at roll count 0) from the last anchor seen
    idx = np.where(anchor, np.arange(n), -1)
    np.maximum.accumulate(idx, out=idx)
    days = np.full(n, -1, dtype=np.int64)
    have = idx >= 0
    days[have] = base[idx[have]] + rolls[have]
    if carry.last_day >= 0:
        before = ~have
        days[before] = carry.last_day + rolls[before]
    elif anchor.any():
        first = int(np.argmax(anchor))
        days[:first] = base[first] + rolls[:first]
    jump = np.full(n, np.nan)
    differs = given & (days >= 0) & (date_days != days)
    jump[differs] = (date_days[differs] - days[differs]).astype(float)
    carry.last_tod_s = float(tod_s[-1])
    if days[-1] >= 0:
        carry.last_day = int(days[-1])
    return days, jump


def first_own_date_contradiction(tod_s: np.ndarray, date_days: np.ndarray, carry: DateCarry) -> tuple[int, int, int] | None:
    """Where a log's own first date (RMC/ZDA) contradicts the date ``--date`` gave: (row, own day, day counted on
    from ``--date`` through the midnights before it), or None (no own date in this chunk, or they agree).

    ``carry.given_day`` is cleared once an own date has been compared."""
    if carry.given_day < 0:
        return None
    own = np.flatnonzero(date_days >= 0)
    if not own.size:
        return None
    k = int(own[0])
    counted, _ = resolve_days(tod_s[: k + 1], np.full(k + 1, -1, dtype=np.int64), DateCarry(carry.last_tod_s, carry.last_day))
    carry.given_day = -1
    if int(counted[-1]) == int(date_days[k]):
        return None
    return k, int(date_days[k]), int(counted[-1])


def to_time_utc_ms(days: np.ndarray, tod_s: np.ndarray) -> np.ndarray:
    """Days + time of day → ``datetime64[ms]`` (NaT where the day is unknown)."""
    ms = days * MS_PER_DAY + np.round(tod_s * 1000.0).astype(np.int64)
    out = ms.astype("datetime64[ms]")
    out[days < 0] = np.datetime64("NaT")
    return out
