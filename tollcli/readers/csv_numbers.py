"""The number columns of a CSV log, checked row by row: a row whose value is not a number where one belongs is
malformed — skipped and counted, or with ``strict`` an error naming the file, line, column and value.

A log read as text first (``dtype=str``) and converted here: a repeated header line, a line cut short at the end of
a truncated file, a NUL byte or a flipped bit inside a number, ``NaN`` where an integer belongs — each is one bad row,
never a crash and never a number made up by a cast (NaN cast to an integer is −9 223 372 036 854 775 808).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError

#: the largest magnitude an integer column may hold (counts, ids, milliseconds and nanoseconds since 1980 fit)
INTEGER_LIMIT = 2**62


#: a plain decimal number: what both parsers read alike (:func:`numbers`)
PLAIN_NUMBER = r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$"


def numbers(text: pd.Series) -> np.ndarray:
    """``pd.to_numeric(text, errors="coerce")`` as float64, the same doubles: where every value given is a plain decimal
    number (:data:`PLAIN_NUMBER`) through Arrow's parser, 30 times faster; else pandas' own (and where Arrow read a
    negative zero, whose sign pandas keeps or not by the column's other values). Both round every decimal string
    correctly (to the nearest double), so the two agree to the bit on plain numbers (tested)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    try:
        strings = pa.array(text)  # the column's own Arrow strings (pandas' default string type), not a copy
        if not (pa.types.is_string(strings.type) or pa.types.is_large_string(strings.type)):
            raise TypeError("not text")
        pool = pa.system_memory_pool()  # (Arrow's default allocator keeps what it freed: 80 MB more at a long log's peak)
        plain = pc.match_substring_regex(strings, PLAIN_NUMBER, memory_pool=pool)
        given = pc.or_kleene(plain, pc.is_null(strings, memory_pool=pool), memory_pool=pool)
        if pc.all(given, memory_pool=pool).as_py() is not False:
            values = np.array(pc.cast(strings, pa.float64(), memory_pool=pool).to_numpy(), float)
            if not ((values == 0.0) & np.signbit(values)).any():  # (pandas reads "-0" as 0 in a column of integers)
                return values
    except (pa.ArrowException, TypeError, ValueError):  # not text (or not castable): pandas says what it is
        pass
    return pd.to_numeric(text, errors="coerce").to_numpy(float)


def checked_numbers(table: pd.DataFrame, path, floats: tuple[str, ...], integers: tuple[str, ...] = (), strict: bool = False,
                    first_line: int = 2, exact: tuple[str, ...] = (), line_numbers: np.ndarray | None = None) -> pd.DataFrame:  # fmt: skip
    """``table`` (read as text) with ``floats`` as float64 (empty: NaN; infinite or not a number: malformed),
    ``integers`` as int64 (missing, fractional or beyond :data:`INTEGER_LIMIT`: malformed) and ``exact`` as nullable
    ``Int64`` read digit for digit (nanosecond counts a float would round; empty: NA; anything but an integer of at
    most 19 digits that fits 64 bits: malformed), its malformed rows dropped; ``attrs['skipped_lines']`` counts them and ``attrs['first_skipped_line']`` names the first (1-based: the
    table's first row is line ``first_line``; or each row's line is given, ``line_numbers``: rows picked from a file
    of other lines too). A column ``line`` holds each kept row's line number."""
    n = len(table)
    bad = np.zeros(n, bool)
    why = np.full(n, "", dtype=object)
    out = {}
    for name in (*floats, *integers):
        text = table[name]
        values = numbers(text) if n else np.zeros(0)
        given = text.notna().to_numpy()
        if name in integers:
            wrong = ~np.isfinite(values) | (np.abs(values) > INTEGER_LIMIT) | (np.floor(values) != values)
        else:
            wrong = (given & np.isnan(values)) | np.isinf(values)
        fresh = wrong & ~bad
        why[fresh] = name
        bad |= wrong
        out[name] = values
    for name in exact:
        text = table[name]
        digits = text.astype("string").fillna("0").str.strip()
        magnitude = digits.str.lstrip("+-")
        wrong = (text.notna() & ~(digits.str.fullmatch(r"[+-]?\d{1,19}") &
                                  ((magnitude.str.len() < 19) | (magnitude <= "9223372036854775807")))).to_numpy()  # fmt: skip
        fresh = wrong & ~bad
        why[fresh] = name
        bad |= wrong
    lines = np.arange(n) + first_line if line_numbers is None else np.asarray(line_numbers, np.int64)
    first = int(lines[bad][0]) if bad.any() else None
    if strict and first is not None:
        name = why[bad][0]
        value = table[name].to_numpy()[bad][0]
        raise DataError(f"{path}:{first}: {name} is not a number ({value!r})")
    keep = ~bad
    result = table.loc[keep].copy()
    for name in floats:
        result[name] = out[name][keep]
    for name in integers:
        result[name] = out[name][keep].astype(np.int64)
    for name in exact:
        result[name] = result[name].astype("string").str.strip().astype("Int64")
    result["line"] = lines[keep]
    result = result.reset_index(drop=True)
    result.attrs["skipped_lines"] = int(bad.sum())
    result.attrs["first_skipped_line"] = first
    return result


def joined_blocks(parts: list[pd.DataFrame]) -> pd.DataFrame:
    """A CSV log's checked blocks (:func:`checked_numbers` each) as one table: their rows in order, and
    ``attrs['skipped_lines']`` / ``attrs['first_skipped_line']`` of them all."""
    table = pd.concat(parts, ignore_index=True)
    table.attrs = {"skipped_lines": sum(p.attrs["skipped_lines"] for p in parts),
                   "first_skipped_line": next((p.attrs["first_skipped_line"] for p in parts if p.attrs["first_skipped_line"]), None)}  # fmt: skip
    return table
