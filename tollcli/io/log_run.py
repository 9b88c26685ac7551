"""One run over a log: the file opened once, its bytes hashed as they are read, its kind told from its head.

A command that reads a log makes one :class:`LogRun` and hands its consumers what they take:

* :meth:`LogRun.stream` — the one streaming pass (a binary stream, gunzipped, named as the log): the navigation
  readers read it block by block, so memory stays that of a block however long the log;
* :meth:`LogRun.replay_path` — for consumers that read the log whole or more than once (Galileo OSNMA pages beside
  the navigation tables, the pseudorange readers that take a path): the same bytes, copied once as they are read
  into a temporary file of this run (removed on :meth:`LogRun.close`), never the log opened again.

:attr:`LogRun.sha256` is the SHA-256 of the bytes as stored (a ``.gz`` log's compressed bytes, what
``sha256sum`` says), taken from the very bytes the consumers were given: the invoice's ``log_sha256`` is the
identity of what was charged. Standard input (``-``) is a log like any other: it can be authenticated (OSNMA)
and hashed too.
"""

from __future__ import annotations

import contextlib
import gzip
import hashlib
import io
import os
import re
import sys
import tempfile
import zlib
from typing import BinaryIO

from tollcli.errors import DataError, TollError
from tollcli.io.sources import GZIP_MAGIC, SNIFF_BYTES, format_of_head, open_raw, printable_path, read_block

#: bytes copied at a time into a replay
COPY_BYTES = 1 << 20


class _HashingReader(io.RawIOBase):
    """A raw stream that updates a SHA-256 with every byte read through it (``hashed=False``: counts them only)."""

    def __init__(self, raw: BinaryIO, name: str, hashed: bool = True):
        self.raw, self.name, self.bytes_read = raw, name, 0
        self.digest = hashlib.sha256() if hashed else None
        self._into = getattr(raw, "readinto", None)

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        if self._into is not None:  # straight into the buffer: no copy
            n = self._into(buffer) or 0
        else:
            data = self.raw.read(len(buffer))
            n = len(data)
            buffer[:n] = data
        if self.digest is not None:
            self.digest.update(memoryview(buffer)[:n])
        self.bytes_read += n
        return n

    def close(self) -> None:
        if self.raw is not sys.stdin.buffer:
            self.raw.close()
        super().close()


class LogRun:
    """A log (a path, a ``.gz`` path or ``-``) opened once (module docstring).

    ``kind``: the input format, ``auto`` to tell it from the head (:func:`tollcli.io.sources.format_of_head`).
    ``hashed=False``: no SHA-256 is taken (what only decodes the log, ``tollcli epochs``; :attr:`sha256` refuses).
    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, log: str, kind: str = "auto", hashed: bool = True):
        self.log = log
        self.name = printable_path(log)
        raw = open_raw(log)
        self._hashing = _HashingReader(raw, self.name, hashed)
        buffered = io.BufferedReader(self._hashing, buffer_size=COPY_BYTES)
        self.compressed = buffered.peek(2)[:2] == GZIP_MAGIC
        self._stream: BinaryIO = gzip.GzipFile(fileobj=buffered, mode="rb") if self.compressed else buffered  # type: ignore[assignment]
        self._buffered = buffered
        self._handed = False
        self._replay: str | None = None
        self.kind = self._sniff() if kind == "auto" else kind
        #: the program that decoded a binary protocol into what the readers read (``gpsdecode 3.25``), else None
        self.decoded_by: str | None = None
        self._decoder = None
        if self.kind == "gpsd-binary":
            self._decode(explicit=kind != "auto")

    def _decode(self, explicit: bool) -> None:
        """A binary protocol gpsd knows: its reports through ``gpsdecode`` (:mod:`tollcli.io.gpsdecode`), read as gpsd
        JSON. Without gpsdecode, a sniffed log is read as NMEA as before (whose error says how to read it)."""
        from tollcli.io.gpsdecode import decoded, gpsdecode_path, gpsdecode_version

        program = gpsdecode_path()
        if program is None and not explicit:
            self.kind = "nmea"
            return
        self._stream, self._decoder = decoded(self._stream, self.name, program)  # type: ignore[assignment]
        self.decoded_by = gpsdecode_version(program)
        self.kind = "gpsd-json"

    # -- what consumers take ----------------------------------------------------------------------
    def stream(self) -> BinaryIO:
        """The log's (gunzipped) bytes, once: the single streaming pass (a second call is an error)."""
        if self._handed or self._replay is not None:
            raise RuntimeError(f"{self.name}: the log was read already")
        self._handed = True
        return _Named(self._stream, self.name)

    def replay_path(self) -> str:
        """A path holding the log's (gunzipped) bytes, for consumers that read it whole or more than once: copied once
        from the one open stream as it is hashed (a temporary file of this run)."""
        if self._replay is None:
            if self._handed:
                raise RuntimeError(f"{self.name}: the log was streamed already")
            self._handed = True
            suffix = os.path.splitext(self.log[:-3] if self.log.endswith(".gz") else self.log)[1] if self.log != "-" else ""
            fd, path = tempfile.mkstemp(prefix="tollcli-log-", suffix=suffix)
            try:
                with os.fdopen(fd, "wb") as out:
                    _copy(self._stream, out, self.name)
            except BaseException:
                os.unlink(path)
                raise
            self._replay = path
        return self._replay

    def head(self, n: int = 4096) -> bytes:
        """The log's first ``n`` (gunzipped) bytes, without reading them away (b"" once the stream is handed out)."""
        if self._handed or self._replay is not None or not hasattr(self._stream, "peek"):
            return b""
        try:
            return self._stream.peek(n)[:n]
        except (OSError, EOFError, zlib.error):
            return b""

    def named(self, text: str) -> str:
        """``text`` naming the log where it names the temporary copy (:meth:`replay_path`)."""
        return text.replace(self._replay, self.name) if self._replay is not None and text else text

    def source(self) -> str | BinaryIO:
        """What a reader of the whole log takes: the replay when there is one, else the one streaming pass."""
        return self._replay if self._replay is not None else self.stream()

    @contextlib.contextmanager
    def named_errors(self):
        """Errors of consumers of the replay name the log, not the temporary copy; a decoded log's line is the
        decoder's report."""
        try:
            yield
        except TollError as exc:
            said = str(exc.args[0]) if exc.args else ""
            named = self.named(said)
            if self.decoded_by:  # a line of a decoded log is one of the decoder's reports, not of the binary file
                named = re.sub(rf"^{re.escape(self.name)}:(\d+):", lambda m: f"{self.name}: {self.decoded_by}'s report {m[1]}:", named)
            if named == said:
                raise
            raise type(exc)(named, *exc.args[1:]) from None

    @property
    def bytes_stored(self) -> int:
        """How many bytes of the log as stored were read so far (all of them once a replay is made)."""
        return self._hashing.bytes_read

    @property
    def sha256(self) -> str:
        """SHA-256 of the log's bytes as stored; reads what no consumer read (a reader that stopped early)."""
        if self._hashing.digest is None:
            raise ValueError(f"{self.name}: opened without hashing")
        if self._decoder is not None:  # the feeder reads the log: let it finish (the reports read away)
            self._decoder.drain()
        while self._buffered.read(COPY_BYTES):
            pass
        return self._hashing.digest.hexdigest()

    # -- life ----------------------------------------------------------------------------------------
    def close(self) -> None:
        if self._replay is not None:
            try:
                os.unlink(self._replay)
            except OSError:
                pass
            self._replay = None
        try:
            self._stream.close()
        except (OSError, EOFError, zlib.error):
            pass

    def __enter__(self) -> LogRun:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _sniff(self) -> str:
        if not hasattr(self._stream, "peek"):
            return format_of_head(b"")
        try:
            head = self._stream.peek(SNIFF_BYTES)[:SNIFF_BYTES]
        except (OSError, EOFError, zlib.error) as exc:
            raise DataError(f"{self.name}: cannot read compressed data ({exc})") from None
        return format_of_head(head)


class _Named(io.BufferedIOBase):
    """A stream that reads through to another and carries the log's name (the readers' messages name it)."""

    def __init__(self, inner: BinaryIO, name: str):
        self.inner, self.name = inner, name

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        return self.inner.read(size)

    def read1(self, size: int = -1) -> bytes:
        return self.inner.read1(size) if hasattr(self.inner, "read1") else self.inner.read(size)

    def readinto(self, buffer) -> int:
        data = self.inner.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def peek(self, size: int = 0) -> bytes:
        return self.inner.peek(size) if hasattr(self.inner, "peek") else b""

    def close(self) -> None:  # the run closes the log
        pass


def _copy(stream: BinaryIO, out: BinaryIO, name: str) -> None:
    """Copy ``stream`` to ``out``: a read that fails is the log's (DataError), a write that fails the disk's (OSError)."""
    while block := read_block(stream, name, COPY_BYTES):
        out.write(block)
