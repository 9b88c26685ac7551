"""Per-epoch picks over the decoded rows of one or more sentence types (the bulk reader's folds).

Rows carry ``e`` (their epoch's place in the block) and ``order`` (their line); epochs follow line
order, so rows of one type are in epoch order and rows of several types are put in it by their
lines. Each function answers, for every epoch at once, a question the reference assembler answers
sentence by sentence: the first or last value given, where a mask holds.
"""

from __future__ import annotations

import numpy as np


def scatter(n: int, e: np.ndarray, values: np.ndarray, fill, dtype=None) -> np.ndarray:
    out = np.full(n, fill, dtype=dtype or np.asarray(values).dtype)
    out[e] = values
    return out


def pick(n: int, sources: list[tuple[dict, np.ndarray, np.ndarray]], fill, last: bool = False) -> np.ndarray:
    """Per epoch, the value of the first (``last``: the last) row in line order where the mask holds.

    ``sources``: (rows with ``e`` and ``order``, values, mask) of one or more sentence types; an epoch
    may have any number of rows of each. ``fill`` where no row qualifies.
    """
    if len(sources) == 1:  # one source is in line order already
        (rows, v, mask), = sources
        e, values = rows["e"][mask], np.asarray(v)[mask]
    else:  # epochs follow line order: sorting by line sorts by epoch too
        e = np.concatenate([rows["e"][mask] for rows, _, mask in sources])
        order = np.concatenate([rows["order"][mask] for rows, _, mask in sources])
        values = np.concatenate([np.asarray(v)[mask] for _, v, mask in sources])
        sort = np.argsort(order, kind="stable")
        e, values = e[sort], values[sort]
    out = np.full(n, fill, dtype=values.dtype if values.size else np.asarray(fill).dtype)
    if e.size:
        edge = np.flatnonzero(np.append(e[1:] != e[:-1], True)) if last else np.flatnonzero(np.r_[True, e[1:] != e[:-1]])
        out[e[edge]] = values[edge]
    return out


def last_finite(n: int, rows: dict, values: np.ndarray) -> np.ndarray:
    """Per epoch, the last finite value in line order (NaN when none)."""
    return pick(n, [(rows, np.asarray(values, float), np.isfinite(values))], np.nan, last=True)


def first_given(n: int, sources: list[tuple[dict, np.ndarray]]) -> np.ndarray:
    """Per epoch, the first non-zero code in line order among the sources (0 when none)."""
    return pick(n, [(rows, np.asarray(v, np.int64), np.asarray(v) != 0) for rows, v in sources], 0)


def first_finite(n: int, sources: list[tuple[dict, np.ndarray]]) -> np.ndarray:
    """Per epoch, the first finite value in line order among the sources (NaN when none)."""
    return pick(n, [(rows, np.asarray(v, float), np.isfinite(v)) for rows, v in sources], np.nan)


def group_seq(e: np.ndarray) -> np.ndarray:
    """Each row's place among the rows of its epoch (``e`` non-decreasing)."""
    if e.size == 0:
        return np.zeros(0, np.int64)
    starts = np.flatnonzero(np.r_[True, e[1:] != e[:-1]])
    return np.arange(e.size) - np.repeat(starts, np.diff(np.append(starts, e.size)))
