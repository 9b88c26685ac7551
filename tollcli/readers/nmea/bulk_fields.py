"""Vectorized NMEA field converters over byte spans of a block (the bulk twins of :mod:`fields`).

Every function takes the block's bytes ``buf`` (uint8 array) and the fields' spans
``start``/``end`` (int64 arrays, end exclusive) and returns the values plus an
``ok`` mask. ``ok`` is False where the text is not in the plain form the bulk
path reads (digits, one dot, a leading minus) or is out of range; those lines are
re-read by the per-line converters, which decide whether they are malformed. Where
``ok`` holds, the value is bit-for-bit what :mod:`fields` gives: a decimal is read
as an exact integer mantissa divided by an exact power of ten, which IEEE division
rounds correctly, as ``float()`` does.
"""

from __future__ import annotations

import numpy as np

from tollcli.readers.nmea import kernels

NAN = np.nan
MAX_WIDTH = 18  # characters; longer fields go to the per-line path
_POW10_INT = 10 ** np.arange(19, dtype=np.int64)
_POW10_FLOAT = 10.0 ** np.arange(23)
_MINUS, _DOT, _ZERO, _NINE = 45, 46, 48, 57


def char_matrix(buf: np.ndarray, start: np.ndarray, end: np.ndarray, width: int = MAX_WIDTH) -> tuple[np.ndarray, np.ndarray]:
    """The fields' characters as an (n, w) uint8 matrix (0 past each field's end) and their lengths."""
    length = end - start
    w = int(min(width, length.max())) if length.size else 0
    cols = np.arange(w)
    inside = cols < length[:, None]
    idx = np.minimum(start[:, None] + cols, buf.size - 1) if buf.size else np.zeros((length.size, w), np.int64)
    chars = np.where(inside, buf[idx] if buf.size else 0, 0).astype(np.uint8)
    return chars, length


_M1, _M2, _M3 = np.uint64(0x00FF00FF00FF00FF), np.uint64(0x0000FFFF0000FFFF), np.uint64(0xFFFFFFFF)
_S8, _S16, _S32, _S56 = np.uint64(8), np.uint64(16), np.uint64(32), np.uint64(56)
_T10, _T100, _T10K = np.uint64(10), np.uint64(100), np.uint64(10_000)
_ONES = np.uint64(0x0101010101010101)  # × bytes of 0/1, >> 56: how many are 1
_PLACES = np.uint64(0x0706050403020100)  # × one 1-byte, >> 56: bytes to its right
_ZEROS = np.uint64(0x3030303030303030)  # eight '0'
_ALL = np.uint64(0xFFFFFFFFFFFFFFFF)


def byte_windows(buf: np.ndarray) -> np.ndarray:
    """``w[i]`` = the eight bytes before ``buf[i]`` as a little-endian uint64 (zeros before the start).

    A strided, unaligned view of the buffer padded with eight zero bytes: no copy per window.
    """
    padded = np.concatenate([np.zeros(8, np.uint8), buf, np.zeros(8, np.uint8)])
    return np.ndarray(shape=(buf.size + 1,), dtype="<u8", buffer=padded, strides=(1,))


def _eight_digits(word: np.ndarray) -> np.ndarray:
    """Eight digit values (0–9, one per byte, first digit in the lowest byte) → their integer, SWAR style."""
    v = (word * _T10 + (word >> _S8)) & _M1
    v = (v * _T100 + (v >> _S16)) & _M2
    return (v * _T10K + (v >> _S32)) & _M3


#: by how many of the eight bytes to keep (0–8): the mask that keeps the last ones, and '0's for the others
_KEEP = np.array([(0xFFFFFFFFFFFFFFFF << (8 * (8 - k))) & 0xFFFFFFFFFFFFFFFF for k in range(9)], dtype=np.uint64)
_FILL = _ZEROS & ~_KEEP


def _word(win: np.ndarray, end: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The eight bytes before ``end``, only the last ``keep`` (0–8) kept, the others made '0'."""
    k = np.minimum(keep, 8)
    return (win[end] & _KEEP[k]) | _FILL[k]


def _byte_counts(word: np.ndarray):
    """Per word of eight characters: bad bytes (neither digit nor point), points, places right of the point, digits."""
    chars = word.view(np.uint8).reshape(word.size, 8)
    d = chars - np.uint8(_ZERO)  # wraps: anything but a digit is > 9
    digit = d < 10
    dot = chars == _DOT
    dots = dot.view(np.uint64).ravel()
    n_bad = (~(digit | dot)).view(np.uint64).ravel() * _ONES >> _S56
    n_dot = dots * _ONES >> _S56
    places = dots * _PLACES >> _S56
    d *= digit
    return n_bad, n_dot, places, d.view(np.uint64).ravel()


def decimal(block, start: np.ndarray, end: np.ndarray, integer_only: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decimal fields → (float value, ok, empty, has_dot); empty fields give NaN and ok.

    By the compiled kernel where it was built, else by :func:`decimal_numpy`: the same values.
    """
    if kernels.compiled is None:
        return decimal_numpy(block, start, end, integer_only)
    start = np.ascontiguousarray(start, np.int64)
    end = np.ascontiguousarray(end, np.int64)
    n = start.size
    value = np.empty(n, np.float64)
    ok, empty, has_dot = np.empty(n, bool), np.empty(n, bool), np.empty(n, bool)
    kernels.compiled.decimal(block.buf, start, end, integer_only, value, ok, empty, has_dot)
    return value, ok, empty, has_dot


def decimal_numpy(block, start: np.ndarray, end: np.ndarray, integer_only: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`decimal` in numpy only (the reference for the compiled kernel).

    ``block``: anything with ``buf`` (uint8) and ``win`` (:func:`byte_windows` of it).
    Each field is read right-aligned as one or two 64-bit words (up to 16
    characters), padded with '0': digits and points counted by multiplying bytes
    of 0/1, the digits' integer by SWAR multiplication, the point read as a zero
    digit. The mantissa is that integer with the point's zero taken out, by exact
    float division and remainder.
    """
    buf, win = block.buf, block.win
    if win is None:
        win = block.win = byte_windows(buf)
    length = end - start
    n = length.size
    empty = length == 0
    bad, dots, places, digits = _byte_counts(_word(win, end, length))
    a = _eight_digits(digits).astype(np.float64)
    long = length > 8
    if long.any():
        hi = np.flatnonzero(long)
        bad2, dots2, places2, digits2 = _byte_counts(_word(win, end[hi] - 8, length[hi] - 8))
        a[hi] += _eight_digits(digits2).astype(np.float64) * 1e8
        places[hi] = np.where(dots[hi] > 0, places[hi], places2 + np.uint64(8))
        bad[hi] += bad2
        dots[hi] += dots2
    neg = buf[np.minimum(start, buf.size - 1)] == _MINUS if buf.size else np.zeros(n, bool)
    has_dot = dots > 0
    ok = (bad == neg) & (dots <= (0 if integer_only else 1)) & (length - dots - neg >= 1) & (length - neg <= 15)
    value = a
    if has_dot.any():  # take the point's zero out: a = high·10^(k+1) + low → high·10^k + low, then / 10^k
        decimals = np.where(ok & has_dot, places, 0)
        scale = _POW10_FLOAT[decimals]
        high = _POW10_FLOAT[decimals + 1]
        r = np.fmod(a, high)
        value = np.where(has_dot, ((a - r) / high * scale + r) / scale, a)
    if neg.any():
        value = np.where(neg, -value, value)
    ok |= empty
    value[~ok | empty] = NAN
    return value, ok, empty, has_dot


def integer(block, start, end, lo: int = 0, hi: int = 32_767, missing: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Integer fields in [lo, hi] → (int64 value, ok); empty → ``missing``."""
    value, ok, empty, _ = decimal(block, start, end, integer_only=True)
    return as_integer(value, ok, empty, lo, hi, missing)


def as_integer(value: np.ndarray, ok: np.ndarray, empty: np.ndarray, lo: int = 0, hi: int = 32_767,
               missing: int = -1) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Fields read by :func:`decimal` with ``integer_only`` → (int64 value, ok) in [lo, hi]; ``value`` is overwritten."""
    value[~ok | empty] = missing
    out = value.astype(np.int64)
    ok &= empty | ((out >= lo) & (out <= hi))
    return out, ok


def time_of_day_s(block, start, end) -> tuple[np.ndarray, np.ndarray]:
    """``hhmmss[.sss]`` fields → (seconds after midnight, ok); empty → NaN.

    By the compiled kernel where it was built, else by :func:`time_of_day_s_numpy`.
    """
    if kernels.compiled is None:
        return time_of_day_s_numpy(block, start, end)
    return _value_and_ok(kernels.compiled.time_of_day, block, start, end, np.float64)


def time_of_day_s_numpy(block, start, end) -> tuple[np.ndarray, np.ndarray]:
    """:func:`time_of_day_s` in numpy only (the reference for the compiled kernel)."""
    buf = block.buf
    length = end - start
    empty = length == 0
    chars, _ = char_matrix(buf, start, np.minimum(end, start + 4))
    digits4 = chars.shape[1] == 4
    if not digits4:
        return np.full(length.size, NAN), empty
    d = chars.astype(np.int64) - _ZERO
    hh = d[:, 0] * 10 + d[:, 1]
    mm = d[:, 2] * 10 + d[:, 3]
    head_ok = ((chars >= _ZERO) & (chars <= _NINE)).all(axis=1) & (length >= 6)
    ss, ss_ok, _, _ = decimal_numpy(block, np.minimum(start + 4, end), end)
    # float("5") and int checks as in fields.time_of_day_s: first six characters digits
    s5 = np.where(length >= 6, buf[np.minimum(start + 4, buf.size - 1)], 0)
    s6 = np.where(length >= 6, buf[np.minimum(start + 5, buf.size - 1)], 0)
    head_ok &= (s5 >= _ZERO) & (s5 <= _NINE) & (s6 >= _ZERO) & (s6 <= _NINE)
    ok = head_ok & ss_ok & (hh <= 23) & (mm <= 59) & (ss >= 0.0) & (ss < 61.0)
    tod = (hh * 3600.0 + mm * 60.0) + ss
    tod = np.where(ok, tod, NAN)
    return tod, ok | empty


def days_from_civil(year: np.ndarray, month: np.ndarray, day: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant's algorithm, vectorized)."""
    y = year - (month <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    mp = (month + 9) % 12
    doy = (153 * mp + 2) // 5 + day - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146_097 + doe - 719_468


def days_in_month(year: np.ndarray, month: np.ndarray) -> np.ndarray:
    leap = ((year % 4 == 0) & (year % 100 != 0)) | (year % 400 == 0)
    table = np.array([0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])
    return table[np.clip(month, 0, 12)] + (leap & (month == 2))


def rmc_date_days(block, start, end) -> tuple[np.ndarray, np.ndarray]:
    """RMC ``ddmmyy`` → (days since 1970-01-01, ok); empty → -1; years 80–99 are 19xx.

    By the compiled kernel where it was built, else by :func:`rmc_date_days_numpy`.
    """
    if kernels.compiled is None:
        return rmc_date_days_numpy(block, start, end)
    return _value_and_ok(kernels.compiled.rmc_date, block, start, end, np.int64)


def _value_and_ok(kernel, block, start, end, dtype) -> tuple[np.ndarray, np.ndarray]:
    """A compiled field kernel's (value, ok) arrays for the spans."""
    start, end = np.ascontiguousarray(start, np.int64), np.ascontiguousarray(end, np.int64)
    value, ok = np.empty(start.size, dtype), np.empty(start.size, bool)
    kernel(block.buf, start, end, value, ok)
    return value, ok


def rmc_date_days_numpy(block, start, end) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rmc_date_days` in numpy only (the reference for the compiled kernel)."""
    buf = block.buf
    length = end - start
    empty = length == 0
    chars, _ = char_matrix(buf, start, np.minimum(end, start + 6))
    if chars.shape[1] < 6:
        return np.full(length.size, -1, np.int64), empty
    digit = ((chars >= _ZERO) & (chars <= _NINE)).all(axis=1) & (length == 6)
    d = chars.astype(np.int64) - _ZERO
    day, month, yy = d[:, 0] * 10 + d[:, 1], d[:, 2] * 10 + d[:, 3], d[:, 4] * 10 + d[:, 5]
    year = np.where(yy >= 80, 1900 + yy, 2000 + yy)
    ok = digit & (month >= 1) & (month <= 12) & (day >= 1) & (day <= days_in_month(year, month))
    days = np.where(ok, days_from_civil(year, month, day), -1)
    return days, ok | empty


def ddmm_deg(raw: np.ndarray, ok: np.ndarray, empty: np.ndarray, letter: np.ndarray, max_deg: float,
             negative: int, positive: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``(d)ddmm.mmmm`` already read as a number + hemisphere letter code → (signed degrees, ok).

    ``letter``: the hemisphere field's character code, 0 when empty, -1 when longer than one character.
    """
    deg = np.floor(raw / 100.0)
    minutes = raw - 100.0 * deg
    out = deg + minutes / 60.0
    with np.errstate(invalid="ignore"):
        ok = ok & (empty | ((raw >= 0) & (minutes >= 0.0) & (minutes < 60.0) & (out <= max_deg)))
    ok &= empty | (letter == 0) | (letter == negative) | (letter == positive)
    out = np.where(letter == negative, -out, out)
    out[~ok | empty] = NAN
    return out, ok
