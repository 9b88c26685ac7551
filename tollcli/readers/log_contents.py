"""What a log holds, message by message: NMEA sentence types, UBX messages, gpsd report classes, record types.

A byte scan, streamed block by block (memory flat in the file's length), that decodes nothing: it counts what
is there, so ``tollcli info`` can say what a receiver wrote before anything is read for charging.
"""

from __future__ import annotations

import re
import struct
from collections import Counter

import numpy as np

from tollcli.io.sources import iter_byte_blocks, open_binary, source_name
from tollcli.readers.ubx_frames import MAX_PAYLOAD

_NMEA = re.compile(rb"[$!]([A-Z][A-Z0-9]{1,5}),")
_GPSD = re.compile(rb'"class"\s*:\s*"([A-Z]+)"')
_RECORD = re.compile(rb"^([A-Za-z][A-Za-z0-9_]*)[, ]", re.M)
BLOCK = 1 << 20
_UBX_SYNC = b"\xb5\x62"


def ubx_name(cls: int, msg_id: int) -> str:
    """A UBX message's name (``NAV-PVT``) from its class and id (``0x01-0x07`` when pyubx2 does not know it)."""
    try:
        from pyubx2.ubxtypes_core import UBX_MSGIDS

        return UBX_MSGIDS.get(bytes((cls, msg_id)), f"0x{cls:02x}-0x{msg_id:02x}")
    except ImportError:  # pragma: no cover - pyubx2 is a dependency
        return f"0x{cls:02x}-0x{msg_id:02x}"


def _nmea_type(address: bytes) -> str:
    """A sentence's type without its talker (``GPGGA`` → ``GGA``); proprietary ``P…`` and short ones as written."""
    text = address.decode("ascii")
    return text if text.startswith("P") or len(text) != 5 else text[2:]


def message_counts(source: str, kind: str) -> dict[str, int]:
    """How many of each message the log holds (by the kind's own names), streamed."""
    stream = open_binary(source)
    name = source_name(source)
    counts: Counter[str] = Counter()
    tail = b""
    try:
        if kind in ("ubx", "ubx-nav"):  # binary: raw blocks, a frame cut by a block's end kept for the next
            while block := stream.read(BLOCK):
                data = tail + block
                tail = _count_ubx(data, counts)
                counts.update(_nmea_type(m.group(1)) for m in _NMEA.finditer(data[: len(data) - len(tail)]))
            return dict(sorted(counts.items()))
        for data in iter_byte_blocks(stream, name):
            if kind == "gpsd-json":
                counts.update(m.group(1).decode() for m in _GPSD.finditer(data))
            elif kind in ("nmea", "unknown"):
                counts.update(_nmea_type(m.group(1)) for m in _NMEA.finditer(data))
            elif kind in ("gnsslogger", "librsf"):
                counts.update(m.group(1).decode() for m in _RECORD.finditer(data))
            elif kind == "rinex":
                counts["epoch records"] += data.count(b"\n> ") + data.startswith(b"> ")
            elif kind == "rtklib-pos":
                counts["solutions"] += sum(1 for line in data.split(b"\n") if line.strip() and not line.startswith(b"%"))
            elif kind in ("gsdc-derived", "device-gnss"):
                counts["measurement rows"] += data.count(b"\n") + 1 - data.startswith(b"MessageType") - data.startswith(b"collectionName")
    finally:
        stream.close()
    return dict(sorted(counts.items()))


def _count_ubx(data: bytes, counts: Counter) -> bytes:
    """Count the whole UBX frames in ``data``; the bytes of a frame cut by the block's end are returned."""
    i = data.find(_UBX_SYNC)
    while i >= 0:
        if i + 6 > len(data):
            return data[i:]
        cls, msg_id, length = struct.unpack_from("<BBH", data, i + 2)
        if length > MAX_PAYLOAD:  # no frame (as the reader frames them): a sync pair inside other data, one byte on
            i = data.find(_UBX_SYNC, i + 2)
            continue
        end = i + 8 + length
        if end > len(data):
            return data[i:]
        body = np.frombuffer(data, np.uint8, end - 2 - (i + 2), i + 2).astype(np.int64)
        a, b = int(body.sum()) & 0xFF, int(np.cumsum(body).sum()) & 0xFF  # the 8-bit Fletcher checksum
        if data[end - 2] == a and data[end - 1] == b:
            counts[ubx_name(cls, msg_id)] += 1
            i = data.find(_UBX_SYNC, end)
        else:
            i = data.find(_UBX_SYNC, i + 2)
    return b""
