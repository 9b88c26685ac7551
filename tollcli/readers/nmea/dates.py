"""Full UTC dates for epochs whose sentences carry only a time of day.

Only RMC (``ddmmyy``) and ZDA carry a date. Every other epoch takes the date of
the nearest dated epoch, counting midnight rollovers in between: a rollover is a
time of day that drops by more than 12 h from one epoch to the next. Epochs
before the first dated one take it backwards the same way. Vectorized over the
epochs of a chunk; :class:`DateCarry` holds what the next chunk needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HALF_DAY_S = 43_200.0
MS_PER_DAY = 86_400_000


@dataclass
class DateCarry:
    """State from the previous chunk: its last time of day and date."""

    last_tod_s: float = float("nan")
    last_day: int = -1  # days since 1970-01-01, -1 unknown


def resolve_days(tod_s: np.ndarray, date_days: np.ndarray, carry: DateCarry) -> np.ndarray:
    """Days since 1970-01-01 per epoch (-1 where no date can be known yet).

    ``tod_s``: time of day per epoch, seconds; ``date_days``: the date an epoch's
    own RMC/ZDA gave, -1 where none. ``carry`` is updated for the next chunk.
    """
    n = tod_s.size
    if n == 0:
        return np.empty(0, dtype=np.int64)
    prev = np.concatenate(([carry.last_tod_s], tod_s[:-1]))
    with np.errstate(invalid="ignore"):
        rolls = np.cumsum(tod_s < prev - HALF_DAY_S).astype(np.int64)
    anchor = date_days >= 0
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
    carry.last_tod_s = float(tod_s[-1])
    if days[-1] >= 0:
        carry.last_day = int(days[-1])
    return days


def to_time_utc_ms(days: np.ndarray, tod_s: np.ndarray) -> np.ndarray:
    """Days + time of day → ``datetime64[ms]`` (NaT where the day is unknown)."""
    ms = days * MS_PER_DAY + np.round(tod_s * 1000.0).astype(np.int64)
    out = ms.astype("datetime64[ms]")
    out[days < 0] = np.datetime64("NaT")
    return out
