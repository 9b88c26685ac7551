"""UBX framing: the frames of a u-blox byte stream, found by their sync pairs and lengths, checked by their
8-bit Fletcher checksums (u-blox interface description, "UBX frame structure").

A frame is ``B5 62``, class, id, a little-endian 16-bit payload length, the payload and CK_A, CK_B over class to
payload. The frames of each block read are found by following their lengths, and the checksums of the whole block
are computed at once from two running sums (:func:`block_checksums`); a bad checksum makes the search start again
two bytes after its sync pair (a false sync pair inside other data, or a damaged frame), as does a length no
message has (more than 8 KiB). A frame cut short by the end of the file is a damaged frame too (``malformed``). Bytes
between frames (NMEA, RTCM, text) are another protocol on the same port.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from tollcli.errors import DataError
from tollcli.readers.nmea.line_reader import ReadStats

SYNC = b"\xb5\x62"
#: the longest payload taken for a frame (a longer length field is a sync pair inside other data)
MAX_PAYLOAD = 8192


def checksum(data: bytes) -> bytes:
    """The UBX 8-bit Fletcher checksum (CK_A, CK_B) over class, id, length and payload."""
    a = b = 0
    for byte in data:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes((a, b))


def frame(cls: int, ident: int, payload: bytes) -> bytes:
    """A whole UBX frame for ``payload`` (for tests and replays)."""
    body = bytes((cls, ident)) + struct.pack("<H", len(payload)) + payload
    return SYNC + body + checksum(body)


def iter_frames(stream: BinaryIO, name: str, stats: ReadStats, strict: bool, block_bytes: int = 1 << 20) -> Iterator[tuple[int, int, bytes, int]]:
    """(class, id, payload, message number) of every UBX frame with a good checksum, in file order.

    ``stats.lines`` counts frames, ``sentences`` good ones, ``bad_checksum`` the others (:func:`iter_frame_blocks`)."""
    for block in iter_frame_blocks(stream, name, stats, strict, block_bytes):
        buf = block.buf
        for k, (start, end) in enumerate(zip(block.starts.tolist(), block.ends.tolist())):
            yield buf[start + 2], buf[start + 3], buf[start + 6 : end - 2], block.first_number + k


@dataclass(frozen=True)
class FrameBlock:
    """Consecutive good UBX frames of one read block: ``buf[starts[k]:ends[k]]`` is the k-th whole frame (sync pair to
    checksum), numbered ``first_number + k`` in the file (1-based)."""

    buf: bytes
    starts: np.ndarray  # int64 offsets of the sync pairs
    ends: np.ndarray  # int64 offsets after the checksums
    first_number: int

    @property
    def classes(self) -> np.ndarray:
        return np.frombuffer(self.buf, np.uint8)[self.starts + 2]

    @property
    def ids(self) -> np.ndarray:
        return np.frombuffer(self.buf, np.uint8)[self.starts + 3]


def iter_frame_blocks(stream: BinaryIO, name: str, stats: ReadStats, strict: bool, block_bytes: int = 1 << 20) -> Iterator[FrameBlock]:
    """The good UBX frames of a stream as :class:`FrameBlock` blocks, in file order: the frames of each block read are
    found by following their lengths and their checksums computed for the block at once (:func:`block_checksums`);
    a bad one is counted (``stats.bad_checksum``, ``first_problem``; an error with ``strict``) and the search starts
    again two bytes after its sync pair; a frame the file ends inside is counted ``stats.malformed`` (and the search
    goes on the same way: the sync pair may be a false one, its length running past the end over real frames).
    ``stats.lines`` counts frames, ``sentences`` good ones."""
    buf = b""
    number = 0
    eof = False
    while not eof or buf:
        if not eof:
            block = stream.read(block_bytes)
            eof = not block
            stats.bytes_read += len(block)
            buf += block
        at, keep = 0, None
        while keep is None or at < keep:
            spans, at, keep = _walk(buf, at, eof)
            if not spans:
                continue
            starts, ends = np.array(spans, np.int64).reshape(-1, 2).T
            tail = np.frombuffer(buf, np.uint8)
            good = block_checksums(buf, starts + 2, ends - 2) == tail[ends - 2].astype(np.int64) * 256 + tail[ends - 1]
            first_bad = len(spans) if good.all() else int(np.argmin(good))
            if first_bad:
                yield FrameBlock(buf, starts[:first_bad], ends[:first_bad], number + 1)
            number += first_bad
            stats.lines += first_bad
            stats.sentences += first_bad
            if first_bad == len(spans):
                continue
            start = spans[first_bad][0]
            number += 1
            _damaged(stats, "bad_checksum", f"{name}: UBX message {number}", "bad checksum",
                     f"(class 0x{buf[start + 2]:02X} id 0x{buf[start + 3]:02X}): bad checksum", strict)  # fmt: skip
            at, keep = start + 2, None  # a false sync pair, or a damaged frame: look again from the next byte
        buf = buf[keep:]
        if eof and buf:  # the file ends inside a frame (or a false sync pair's length runs past it): counted, and the
            # search goes on two bytes after its sync pair, as after a bad checksum
            number += 1
            _damaged(stats, "malformed", f"{name}: UBX message {number}", "cut short by the end of the file",
                     f": cut short by the end of the file ({len(buf)} bytes from its sync pair)", strict)  # fmt: skip
            buf = buf[2:]


def _damaged(stats: ReadStats, counter: str, where: str, what: str, strict_detail: str, strict: bool) -> None:
    """A damaged frame at ``where`` (file and message): counted in ``stats`` (``counter``; the first problem, ``what``),
    or with ``strict`` an error (``where`` + ``strict_detail``)."""
    stats.lines += 1
    setattr(stats, counter, getattr(stats, counter) + 1)
    if not stats.first_problem:
        stats.first_problem = f"{where}: {what}"
    if strict:
        raise DataError(where + (" " if strict_detail.startswith("(") else "") + strict_detail)


#: frames checked at once (a damaged frame makes the ones after it be walked again: at most this many)
_WALK_FRAMES = 2048


def _walk(buf: bytes, at: int, eof: bool) -> tuple[list[tuple[int, int]], int, int | None]:
    """Up to ``_WALK_FRAMES`` frames of ``buf`` from ``at`` on, found by their sync pairs and lengths (checksums not
    checked): their (start, end) offsets, where the walk stopped, and — when it stopped at the buffer's end —
    where the bytes kept for the next block begin (a frame cut by the block's end, or a last sync byte; at the
    end of the file, a frame the file ends inside, else nothing), else None."""
    spans = []
    n = len(buf)
    while len(spans) < _WALK_FRAMES:
        start = buf.find(SYNC, at)
        if start < 0:
            return spans, n, (n - 1 if buf.endswith(SYNC[:1]) and not eof else n)
        if n < start + 6:
            return spans, n, start
        length = buf[start + 4] | (buf[start + 5] << 8)
        if length > MAX_PAYLOAD:  # no frame: a sync pair inside other data
            at = start + 2
            continue
        end = start + 8 + length
        if n < end:
            return spans, n, start
        spans.append((start, end))
        at = end
    return spans, at, None


def block_checksums(buf: bytes, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The UBX Fletcher checksums (CK_A·256 + CK_B) of the byte ranges [starts, ends) of ``buf``, all at once:
    CK_A = Σ b_i, CK_B = Σ (end − i)·b_i (mod 256), from two running sums over the buffer."""
    if not len(starts):
        return np.zeros(0, np.int64)
    low, top = int(starts.min()), int(ends.max())
    b = np.frombuffer(buf, np.uint8, count=top - low, offset=low).astype(np.int64)
    c1 = np.concatenate([[0], np.cumsum(b)])
    ci = np.concatenate([[0], np.cumsum(b * np.arange(top - low, dtype=np.int64))])
    s, e = starts - low, ends - low
    a = c1[e] - c1[s]
    weighted = e * a - (ci[e] - ci[s])
    return (a % 256) * 256 + weighted % 256
