"""A block of NMEA text as arrays: line spans, checksums, addresses and field spans, without a loop per line.

A line is *plain* when it is ``$AAAAA,...*HH``: ``$`` first (after Android's
``NMEA,`` prefix), a five-letter address, a hex checksum (either case), no other
``$``, ``!``, ``*`` or carriage return; what follows the checksum is ignored, as
the reference reader does (Android's time stamp). Plain lines are verified and split here in bulk; every other line
(blank, comment, Android ``NMEA,`` prefix, AIS, junk) is left
to the per-line classifier, which the reference reader uses for every line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.readers.nmea import kernels
from tollcli.readers.nmea.bulk_fields import byte_windows, decimal

_NL, _CR, _DOLLAR, _BANG, _STAR, _COMMA = 10, 13, 36, 33, 42, 44


def _hex_value(chars: np.ndarray) -> np.ndarray:
    """Hex digits (either case, as ``int(text, 16)``) → 0–15; anything else → -1."""
    out = np.full(chars.shape, -1, np.int64)
    digit = (chars >= 48) & (chars <= 57)
    upper = (chars >= 65) & (chars <= 70)
    lower = (chars >= 97) & (chars <= 102)
    out[digit] = chars[digit].astype(np.int64) - 48
    out[upper] = chars[upper].astype(np.int64) - 55
    out[lower] = chars[lower].astype(np.int64) - 87
    return out


@dataclass
class BlockLines:
    """The lines of one block: spans into ``buf`` and, for plain lines, their decoded framing."""

    buf: np.ndarray  # uint8, the block's bytes
    win: np.ndarray | None  # bulk_fields.byte_windows(buf), for the numpy kernels (None: made when needed)
    start: np.ndarray  # first byte of each line
    end: np.ndarray  # one past the last byte (line feed and a final carriage return excluded; plain: the checksum's)
    plain: np.ndarray  # bool: the bulk path can read this line
    checksum_ok: np.ndarray  # bool (plain lines): the checksum matches
    given: np.ndarray  # the checksum written on the line (plain lines)
    computed: np.ndarray  # the checksum of the body (plain lines)
    address: np.ndarray  # int64: the five address bytes packed big-endian (plain lines)
    commas: np.ndarray  # positions of every comma in the block, then two sentinels
    first_comma: np.ndarray  # index into ``commas`` of each line's first comma
    n_fields: np.ndarray  # fields after the address (plain lines)
    n_special: np.ndarray  # '$', '!', '*' and carriage returns in the line (after an Android prefix)
    line_start: np.ndarray | None = None  # where each line starts, where reframe_glued moved a start

    def text(self, i: int) -> str:
        """Line ``i`` as the reference reader sees it (latin-1, carriage returns removed)."""
        return self.buf[self.start[i] : self.end[i]].tobytes().decode("latin-1").replace("\r", "")

    def field_span(self, lines: np.ndarray, k: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Start and end of field ``k`` (1 = first after the address) of plain ``lines``; empty past the last.

        Field ``k`` starts after the line's ``k``-th comma and ends at the next comma
        or at the ``*``, whichever comes first; past the last field it starts beyond
        the ``*`` and is made empty.
        """
        if kernels.compiled is not None:
            lines = np.ascontiguousarray(lines, np.int64)
            k = np.ascontiguousarray(k, np.int64).ravel()
            s, e = np.empty(lines.size, np.int64), np.empty(lines.size, np.int64)
            kernels.compiled.field_span(self.first_comma, self.end, self.commas, lines.ravel(), k, s, e)
            return s.reshape(lines.shape), e.reshape(lines.shape)
        return self.field_span_numpy(lines, k)

    def field_decimals(self, lines: np.ndarray, k: np.ndarray | int, integer_only: bool = False):
        """Field ``k`` of plain ``lines`` read as decimals: (value, ok, empty, has_dot), as
        :func:`~tollcli.readers.nmea.bulk_fields.decimal` of :meth:`field_span` (in one compiled pass where built)."""
        if kernels.compiled is None:
            return decimal(self, *self.field_span_numpy(lines, k), integer_only)
        lines = np.ascontiguousarray(lines, np.int64).ravel()
        k = np.ascontiguousarray(k, np.int64).ravel()
        n = lines.size
        value = np.empty(n, np.float64)
        ok, empty, has_dot = np.empty(n, bool), np.empty(n, bool), np.empty(n, bool)
        kernels.compiled.field_decimal(self.buf, self.first_comma, self.end, self.commas, lines, k, integer_only,
                                       value, ok, empty, has_dot)  # fmt: skip
        return value, ok, empty, has_dot

    def field_span_numpy(self, lines: np.ndarray, k: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`field_span` in numpy only (the reference for the compiled kernel)."""
        c = np.minimum(self.first_comma[lines] + (np.asarray(k) - 1), self.commas.size - 2)
        star = self.end[lines] - 3
        s = self.commas[c] + 1
        e = np.minimum(np.maximum(self.commas[c + 1], s), star)  # past the last field: empty, at the '*'
        return np.minimum(s, star), e


_ANDROID = np.uint64(int.from_bytes(b"NMEA,", "little"))


_SENTINEL = np.iinfo(np.int64).max // 2  # after the last comma: no line reaches it


def split_block(data: bytes) -> BlockLines:
    """Split ``data`` (whole lines, without the last one's line feed) and frame its plain lines.

    By the compiled kernel where it was built (one pass per line), else by
    :func:`split_block_numpy`: the same arrays.
    """
    if kernels.compiled is None:
        return split_block_numpy(data)
    buf = np.frombuffer(data, dtype=np.uint8)
    n = int(np.count_nonzero(buf == _NL)) + 1
    start, end, given, computed, address, first_comma, n_fields, n_special = (np.empty(n, np.int64) for _ in range(8))
    plain = np.empty(n, bool)
    commas = np.empty(int(np.count_nonzero(buf == _COMMA)) + 2, np.int64)
    commas[-2:] = _SENTINEL
    kernels.compiled.frame(buf, start, end, plain, given, computed, address, commas, first_comma, n_fields, n_special)
    checksum_ok = plain & (computed == given)
    return BlockLines(buf, None, start, end, plain, checksum_ok, given, computed, address, commas,
                      first_comma, n_fields, n_special)  # fmt: skip


def split_block_numpy(data: bytes) -> BlockLines:
    """:func:`split_block` in numpy only (the reference for the compiled kernel)."""
    buf = np.frombuffer(data, dtype=np.uint8)
    win = byte_windows(buf)
    nl = np.flatnonzero(buf == _NL)
    start = np.concatenate(([0], nl + 1))
    end = np.append(nl, buf.size)
    n = start.size
    if buf.size:
        end = end - ((end > start) & (buf[np.maximum(end - 1, 0)] == _CR))
    specials = np.flatnonzero((buf == _DOLLAR) | (buf == _BANG) | (buf == _STAR) | (buf == _CR))  # counted per line
    # an Android GnssLogger line carries "NMEA," before the sentence (and its time after the checksum)
    android = (win[np.minimum(start + 8, buf.size)] & 0xFFFFFFFFFF) == _ANDROID
    start = np.where(android, start + 5, start)
    last = np.searchsorted(specials, end) - 1
    n_special = np.maximum(last + 1 - np.searchsorted(specials, start), 0)  # none where a prefix passes the end
    # the sentence ends two characters after its '*' (the reference reader ignores what follows)
    star = np.where(n_special > 0, specials[np.clip(last, 0, max(specials.size - 1, 0))] if specials.size else 0, end)
    framed = np.minimum(star + 3, end)
    head = win[np.minimum(start + 8, buf.size)]  # the first eight bytes of each sentence, little-endian
    tail = win[framed]  # the last eight
    length = framed - start
    plain = (length >= 10) & ((head & 0xFF) == _DOLLAR) & (buf[np.clip(star, 0, max(buf.size - 1, 0))] == _STAR) if buf.size else np.zeros(n, bool)
    plain &= (n_special == 2) & (star + 3 <= end) & (((head >> 48) & 0xFF) == _COMMA)
    hi = _hex_value(((tail >> 48) & 0xFF).astype(np.uint8))
    lo = _hex_value(((tail >> 56) & 0xFF).astype(np.uint8))
    plain &= (hi >= 0) & (lo >= 0)
    for k in range(1, 6):  # a five-character address: "$GNG,A,..." is not one
        plain &= ((head >> (8 * k)) & 0xFF) != _COMMA
    given = hi * 16 + lo
    end = np.where(plain, framed, end)
    start = np.where(plain | ~android, start, start - 5)  # lines left to the per-line reader keep their prefix
    # XOR of each plain line's body, between '$' and '*'
    computed = np.full(n, -1, np.int64)
    p = np.flatnonzero(plain)
    if p.size:
        bounds = np.empty(2 * p.size, np.int64)
        bounds[0::2] = start[p] + 1
        bounds[1::2] = end[p] - 3
        computed[p] = np.bitwise_xor.reduceat(buf, bounds)[0::2]
    checksum_ok = plain & (computed == given)
    address = ((head >> 8) & 0xFFFFFFFFFF).astype(np.int64)  # the five characters after '$'
    commas = np.flatnonzero(buf == _COMMA)
    first_comma = np.searchsorted(commas, start + 6)
    last_comma = np.searchsorted(commas, end - 3)
    n_fields = last_comma - first_comma  # commas after the address = fields after it
    commas = np.append(commas, np.full(2, _SENTINEL))  # sentinels: no line reaches them
    return BlockLines(buf, win, start, end, plain, checksum_ok, given, computed, address, commas, first_comma, n_fields,
                      n_special.astype(np.int64))  # fmt: skip


def pack_address(text: str) -> int:
    """``"GPGGA"`` → the int :func:`split_block` gives (first character in the lowest byte)."""
    return int.from_bytes(text.encode("latin-1"), "little")


def unpack_address(value: int) -> str:
    return int(value).to_bytes(5, "little").decode("latin-1")


def type_code(address: np.ndarray) -> np.ndarray:
    """The sentence type (characters 3–5 of the address) of packed addresses."""
    return address >> 16


def talker_code(address: np.ndarray) -> np.ndarray:
    """The talker (characters 1–2) of packed addresses."""
    return address & 0xFFFF


def _checksum_at_end(buf: np.ndarray, start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lines ending in ``*HH`` (a hex checksum, either case), at least 10 characters long: (mask, HH's value)."""
    last = max(buf.size - 1, 0)
    ok = (end - start >= 10) & (buf[np.clip(end - 3, 0, last)] == _STAR)
    hi, lo = _hex_value(buf[np.clip(end - 2, 0, last)]), _hex_value(buf[np.clip(end - 1, 0, last)])
    return ok & (hi >= 0) & (lo >= 0), hi * 16 + lo


def _body_xor(buf: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """XOR of ``buf[start:stop]`` for each span (0 for an empty one): the checksum of a sentence's body."""
    start, stop = np.minimum(start, buf.size), np.minimum(stop, buf.size)
    bounds = np.empty(2 * start.size, np.int64)
    bounds[0::2] = start
    bounds[1::2] = np.maximum(stop, start)
    data = buf if bounds.size == 0 or bounds.max() < buf.size else np.append(buf, np.uint8(0))  # reduceat's bounds < size
    xor = np.bitwise_xor.reduceat(data, bounds)[0::2].astype(np.int64)
    return np.where(stop > start, xor, 0)


#: longest address :func:`other_sentences` names (longer ones go the per-line way)
MAX_OTHER_ADDRESS = 8
MAX_OTHER_LINE = 256  # characters (NMEA allows 82)


def other_sentences(bl: BlockLines, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Of the non-plain lines ``idx``: those that are whole sentences the reader does not use.

    That is ``$ADDRESS,...*HH`` with nothing before the ``$`` or after the checksum, no
    other ``$``, ``!``, ``*`` or carriage return, a hex checksum and an address
    that is not five characters or is proprietary (``$PSTI``, u-blox ``$GYOACC``): what the
    per-line classifier calls ``unused`` (or ``bad_checksum``). Returns ``(framed,
    given, computed, names)`` for every line of ``idx``: the checksum written and the one of
    the body, and the address of each framed line (``""`` elsewhere); lines longer than
    :data:`MAX_OTHER_LINE` and the other lines stay with the per-line classifier.
    """
    n = idx.size
    if n == 0 or bl.buf.size == 0:
        return np.zeros(n, bool), np.zeros(n, np.int64), np.zeros(n, np.int64), np.full(n, "", dtype=object)
    buf = bl.buf
    s, e = bl.start[idx], bl.end[idx]
    framed, given = _checksum_at_end(buf, s, e)
    framed &= (e - s <= MAX_OTHER_LINE) & (buf[np.minimum(s, buf.size - 1)] == _DOLLAR)
    framed &= bl.n_special[idx] == 2  # no other '$', '!', '*' or carriage return
    star = np.where(framed, e - 3, s)
    computed = _body_xor(buf, s + 1, star)
    # the address: up to the first comma or the '*'
    c = np.searchsorted(bl.commas, s + 1)
    stop = np.minimum(bl.commas[c], star)
    name_len = stop - s - 1
    framed &= (name_len >= 1) & (name_len <= MAX_OTHER_ADDRESS) & ((name_len != 5) | (buf[np.minimum(s + 1, buf.size - 1)] == ord("P")))
    names = np.full(n, "", dtype=object)
    if framed.any():
        f = np.flatnonzero(framed)
        width = np.arange(MAX_OTHER_ADDRESS)
        head = np.where(width < name_len[f, None], buf[np.minimum(s[f, None] + 1 + width, buf.size - 1)], 0).astype(np.uint8)
        packed = np.zeros(n, np.uint64)
        packed[f] = np.ascontiguousarray(head).view("<u8").ravel()  # the address's bytes, first in the lowest
        codes, inverse = np.unique(packed[framed], return_inverse=True)
        text = np.array([int(c).to_bytes(8, "little").rstrip(b"\0").decode("latin-1") for c in codes], dtype=object)
        names[framed] = text[inverse.ravel()]
    return framed, given, computed, names


#: the bytes Python's ``str.strip`` removes (latin-1): text made of them before a sentence is not "discarded"
_WHITESPACE = bytes(c for c in range(256) if chr(c).isspace())


def reframe_glued(bl: BlockLines) -> np.ndarray:
    """Frame the sentence at the end of lines with text before it (binary UBX bytes, a doubled ``$``).

    As the per-line classifier: the sentence starts at the last ``$`` before the line's last ``*``.
    A non-plain line whose sentence is ``$AAAAA,...*HH`` at the line's end (no ``!`` after the ``$``,
    no ``*`` or carriage return inside, not an Android line or a comment) is made plain in ``bl`` (its start,
    address, fields and checksums); the rest stays with the per-line classifier. Returns the lines
    reframed whose text before the sentence was not only whitespace (the classifier's "discarded").
    """
    if bl.buf.size < 10:
        return np.zeros(0, np.int64)
    buf = bl.buf
    # text before a '$': the line does not start with one, or has another special character
    cand = np.flatnonzero(~bl.plain & ((buf[np.minimum(bl.start, buf.size - 1)] != _DOLLAR) | (bl.n_special > 2)))
    ok, given = _checksum_at_end(buf, bl.start[cand], bl.end[cand])
    cand, given = cand[ok], given[ok]
    s0, e = bl.start[cand], bl.end[cand]
    star = e - 3
    if cand.size == 0:
        return cand

    def last_before(char: int, at: np.ndarray) -> np.ndarray:
        """Position of the last ``char`` before ``at`` (-1 when none)."""
        where = np.flatnonzero(buf == char)
        i = np.searchsorted(where, at) - 1
        return np.where(i >= 0, where[np.maximum(i, 0)] if where.size else -1, -1)

    ns = last_before(_DOLLAR, star)
    ok = (ns > s0) & (star - ns >= 7)
    ok &= last_before(_BANG, star) < ns
    ok &= last_before(_STAR, star) < ns
    ok &= last_before(_CR, star) < ns
    head = np.clip(ns[:, None] + np.arange(1, 7), 0, buf.size - 1)
    ok &= (buf[head[:, :5]] != _COMMA).all(axis=1) & (buf[head[:, 5]] == _COMMA)
    cand, s0, e, star, given, ns, head = (a[ok] for a in (cand, s0, e, star, given, ns, head))
    # the text before the sentence, as the classifier sees it (stripped)
    before = [bytes(buf[a:b]).lstrip(_WHITESPACE) for a, b in zip(s0.tolist(), ns.tolist())]
    ok = np.array([not t.startswith((b"NMEA,", b"#")) for t in before], bool)  # an Android line, a comment
    discarded = np.array([t.rstrip(_WHITESPACE) != b"" for t in before], bool)
    cand, s0, e, star, given, ns, head, discarded = (a[ok] for a in (cand, s0, e, star, given, ns, head, discarded))
    if cand.size == 0:
        return cand
    computed = _body_xor(buf, ns + 1, star)
    address = np.zeros(cand.size, np.int64)
    for k in range(4, -1, -1):
        address = (address << 8) | buf[head[:, k]].astype(np.int64)
    first = np.searchsorted(bl.commas, ns + 6)
    bl.line_start = bl.start.copy()
    bl.start[cand], bl.end[cand], bl.plain[cand] = ns, e, True
    bl.given[cand], bl.computed[cand] = given, computed
    bl.checksum_ok[cand] = computed == given
    bl.address[cand], bl.first_comma[cand] = address, first
    bl.n_fields[cand] = np.searchsorted(bl.commas, star) - first
    return cand[discarded]
