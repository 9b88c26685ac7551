"""Open a log given as a path, a ``.gz`` path or ``-`` (stdin), and read it in blocks."""

from __future__ import annotations

import gzip
import hashlib
import io
import os
import re
import sys
import zlib
from collections.abc import Iterator
from typing import BinaryIO

from tollcli.errors import DataError, TollError, UsageError

BLOCK_BYTES = 1 << 21
GZIP_MAGIC = b"\x1f\x8b"


def printable_path(path: str) -> str:
    """A path as text that can be written anywhere: bytes of a file name that are not UTF-8 as ``\\xNN``."""
    return path.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def source_name(source: str | os.PathLike | BinaryIO) -> str:
    """A printable name for messages (``-`` for stdin)."""
    if isinstance(source, (str, os.PathLike)):
        return os.fspath(source)
    return getattr(source, "name", "<stream>")


def open_raw(path: str) -> BinaryIO:
    """The raw bytes of a log path (``-``: stdin), opened once; UsageError for a missing path or a directory."""
    if path == "-":
        return sys.stdin.buffer
    if not os.path.exists(path):
        raise UsageError(f"{printable_path(path)}: no such file")
    if os.path.isdir(path):
        raise UsageError(f"{printable_path(path)}: is a directory, expected a log file")
    try:
        return open(path, "rb")  # noqa: SIM115 - closed by the caller
    except OSError as exc:
        raise UsageError(f"{printable_path(path)}: cannot open ({exc.strerror})") from None


def open_binary(source: str | os.PathLike | BinaryIO) -> BinaryIO:
    """A binary stream for ``source``, transparently gunzipped.

    Raises :class:`UsageError` for a missing path or a directory.
    """
    raw: BinaryIO = open_raw(os.fspath(source)) if isinstance(source, (str, os.PathLike)) else source
    buffered = raw if hasattr(raw, "peek") else io.BufferedReader(raw)  # type: ignore[arg-type]
    if buffered.peek(2)[:2] == GZIP_MAGIC:
        return gzip.GzipFile(fileobj=buffered, mode="rb")  # type: ignore[return-value]
    return buffered  # type: ignore[return-value]


def read_block(stream: BinaryIO, name: str, size: int) -> bytes:
    """Up to ``size`` bytes of a (possibly gunzipping) stream; a damaged compressed stream is a DataError naming ``name``."""
    try:
        return stream.read(size)
    except (OSError, EOFError, zlib.error) as exc:
        raise DataError(f"{name}: cannot read compressed data ({exc})") from None


_CR_BEFORE_LF = re.compile(rb"\r+(?=\n)")
_CR_LINE_END = re.compile(rb"\r(?=[$!#\r])")


def normalize_line_ends(data: bytes) -> bytes:
    """Line ends as line feeds: CR LF (and CR CR LF) → LF; a lone CR before a sentence (``$``, ``!``), a
    comment (``#``) or another line end → LF. Data without lone CRs is returned as it is (the readers drop
    the CR of CR LF themselves); a CR inside binary bytes that starts no sentence is left alone.
    """
    if b"\r" not in data:
        return data
    import numpy as np

    byte = np.frombuffer(data, np.uint8)
    cr = np.flatnonzero(byte[:-1] == 13)  # a CR as the very last byte waits for what follows it
    if not (byte[cr + 1] != 10).any():
        return data
    return _CR_LINE_END.sub(b"\n", _CR_BEFORE_LF.sub(b"", data))


def iter_byte_blocks(stream: BinaryIO, name: str, block_bytes: int = BLOCK_BYTES) -> Iterator[bytes]:
    """Yield blocks of complete lines as bytes, each without its last line feed.

    A line ends with LF, CR LF or a lone CR (:func:`normalize_line_ends`): a log written with
    any of them, or a mix, gives the same lines. Memory is bounded by ``block_bytes`` plus the
    longest line.
    """
    rest = b""
    while True:
        block = read_block(stream, name, block_bytes)
        if not block:
            break
        data = normalize_line_ends(rest + block)  # a CR at the very end waits in ``rest`` for what follows it
        cut = data.rfind(b"\n")
        if cut < 0:
            if len(data) > 4 * block_bytes:  # no line end in sight: binary junk
                yield data
                data = b""
            rest = data
            continue
        rest = data[cut + 1 :]
        yield data[:cut]
    if rest:
        yield rest


def iter_text_blocks(stream: BinaryIO, name: str, block_bytes: int = BLOCK_BYTES) -> Iterator[list[str]]:
    """Yield lists of complete lines (latin-1 decoded, ``\\r`` removed)."""
    for block in iter_byte_blocks(stream, name, block_bytes):
        yield block.decode("latin-1").replace("\r", "").split("\n")


def file_sha256(path: str) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MiB blocks (an input's identity in invoices and caches)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_json(path: str, what: str):
    """A whole JSON document, or a one-line DataError naming the file and saying it is not a ``what``."""
    import json

    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh, parse_constant=_not_json)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # (ValueError: not JSON, or an integer of over 4 300 digits)
        raise DataError(f"{path}: not {what} ({' '.join(str(exc).split())[:200]})") from None
    except RecursionError:
        raise DataError(f"{path}: not {what} (nested too deeply)") from None


def _not_json(constant: str):
    """``NaN``, ``Infinity``, ``-Infinity``: what Python's json reads and JSON does not have."""
    raise ValueError(f"{constant} is not a JSON number")


#: the input formats (``--format``): ``auto`` is :func:`sniff_format`
INPUT_KINDS = ("auto", "nmea", "ubx-nav", "gpsd-json", "gpsd-binary", "rtklib-pos", "gsdc-derived", "rinex", "gnsslogger", "device-gnss",
               "ubx", "librsf")  # fmt: skip
#: a u-blox RXM-RAWX frame's first bytes (sync chars, class 0x02, id 0x15)
UBX_RAWX = b"\xb5\x62\x02\x15"
#: the first bytes of u-blox frames that carry the receiver's position (NAV-PVT, NAV-SOL, NAV-POSLLH, HNR-PVT)
UBX_NAV_POSITIONS = (b"\xb5\x62\x01\x07", b"\xb5\x62\x01\x06", b"\xb5\x62\x01\x02", b"\xb5\x62\x28\x02")
SNIFF_BYTES = 1 << 16


def sniff_format(log: str) -> str:
    """The log's kind from its first bytes (stdin: the bytes a pipe has ready; gzip on stdin: ``nmea``):
    ``gsdc-derived`` or ``device-gnss`` (their CSV headers), ``rinex`` (the RINEX header), ``gnsslogger`` (a
    ``# Raw,`` header line), ``ubx`` (a u-blox ``RXM-RAWX`` frame in the first 64 KiB: raw measurements),
    ``ubx-nav`` (a u-blox NAV-PVT, NAV-SOL, NAV-POSLLH or HNR-PVT frame, wherever it starts: after text,
    comments or NMEA), ``rtklib-pos`` (an RTKLIB solution file's ``%`` header), ``librsf`` (a ``pseudorange3``/``odom3``/``point3`` line first), ``gpsd-json`` (a
    gpsd report as the first line that is no comment, or a TPV line), ``gpsd-binary`` (a binary protocol without NMEA:
    read through gpsd's ``gpsdecode``, :mod:`tollcli.io.gpsdecode`), else ``nmea``."""
    if log == "-":
        try:  # a pipe's first bytes, left for the reader (``gpspipe -w | tollcli integrity -``)
            head = sys.stdin.buffer.peek(SNIFF_BYTES)[:SNIFF_BYTES]  # type: ignore[attr-defined]
        except (AttributeError, OSError, ValueError):
            return "nmea"
        return "nmea" if head[:2] == GZIP_MAGIC else format_of_head(head)
    return format_of_head(read_head(log))


def read_head(log: str) -> bytes:
    """The first ``SNIFF_BYTES`` of a log (decompressed)."""
    stream = open_binary(log)
    try:
        return read_block(stream, log, SNIFF_BYTES)
    finally:
        stream.close()


def format_of_head(head: bytes) -> str:
    """:func:`sniff_format` of a log's first bytes."""
    first = head.split(b"\n", 1)[0]
    if b"millisSinceGpsEpoch" in first:
        return "gsdc-derived"
    if b"FullBiasNanos" in first and b"ReceivedSvTimeNanos" in first:
        return "device-gnss"
    if b"RINEX VERSION" in first:
        return "rinex"
    if head.startswith(b"% program") or head.startswith((b"%  GPST ", b"%  UTC ", b"%  JST ")):
        return "rtklib-pos"
    if b"\n# Raw," in head or head.startswith(b"# Raw,"):
        return "gnsslogger"
    if UBX_RAWX in head:
        return "ubx"
    if any(m in head for m in UBX_NAV_POSITIONS):
        return "ubx-nav"
    if head.lstrip().startswith((b"pseudorange3 ", b"odom3 ", b"point3 ")):
        return "librsf"
    if _first_line(head).startswith(b'{"class"') or b'\n{"class":"TPV"' in head:
        return "gpsd-json"
    if _binary_without_nmea(head):
        return "gpsd-binary"
    return "nmea"


#: the share of bytes that are not text above which a log with no NMEA sentence is a binary protocol
BINARY_SHARE = 0.3


def _binary_without_nmea(head: bytes) -> bool:
    """A binary protocol: after the ``#`` comment lines (gpsd's test logs start with some), at least 64 bytes, over
    :data:`BINARY_SHARE` of them not text, and no NMEA sentence (a receiver that mixes NMEA in is read as NMEA)."""
    lines = head.split(b"\n")
    comments = next((i for i, line in enumerate(lines) if not line.startswith(b"#")), len(lines))
    body = b"\n".join(lines[comments:])
    if len(body) < 64 or _NMEA_SENTENCE.search(body):
        return False
    text = len(body) - len(body.translate(None, _TEXT_BYTES))
    return 1.0 - text / len(body) > BINARY_SHARE


_TEXT_BYTES = bytes([9, 10, 13, *range(32, 127)])


def _first_line(head: bytes) -> bytes:
    """The first line of a log that is neither blank nor a ``#`` comment."""
    for line in head.split(b"\n", 64)[:64]:
        line = line.strip()
        if line and not line.startswith(b"#"):
            return line
    return b""


_NMEA_SENTENCE = re.compile(rb"[$!][A-Z]{2}[A-Z0-9]{2,4},")


def looks_like_log(path: str) -> bool:
    """Whether a file's first bytes are a receiver log of a kind tollcli reads (a pseudorange header, RINEX,
    GnssLogger, u-blox, or an NMEA sentence): a folder's ``notes.txt`` is not one."""
    try:
        head = read_head(path)
    except (OSError, TollError):
        return True  # unreadable: processing it says why
    return format_of_head(head) != "nmea" or bool(_NMEA_SENTENCE.search(head)) or b"\xb5\x62" in head


def read_table(path: str):
    """A CSV or Parquet table (by extension) as a pandas DataFrame; one-line errors."""
    import pandas as pd

    if not os.path.exists(path):
        raise UsageError(f"{path}: no such file")
    try:
        if path.lower().endswith(".parquet"):
            return pd.read_parquet(path)
        return pd.read_csv(path)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not a readable table ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
