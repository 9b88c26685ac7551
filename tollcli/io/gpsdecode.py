"""A binary receiver protocol read through gpsd's ``gpsdecode``, as the log is read.

gpsd knows the binary protocols of many receivers (SiRF, Javad GREIS, Motorola Oncore, Zodiac, NavCom, Garmin,
iTalk, SuperStar II, Geostar, …); tollcli reads their positions as gpsd reports them (gpsd JSON: TPV, SKY, GST).
:class:`DecodedStream` runs ``gpsdecode`` (Debian package ``gpsd-clients``) on the log's bytes: a thread feeds it
the bytes from the log's one open stream (hashed as they pass, :mod:`tollcli.io.log_run`), and the readers read its
JSON reports as they come — memory stays that of a pipe's buffer however long the log.

``gpsdecode``'s version is part of what a charge rests on (:func:`gpsdecode_version`): a re-run with another version
may read other positions, and the invoice records it.
"""

from __future__ import annotations

import io
import shutil
import subprocess
import tempfile
import threading
from functools import lru_cache
from typing import BinaryIO

from tollcli.errors import DataError

#: bytes handed to gpsdecode at a time
FEED_BYTES = 1 << 16
#: what a user without gpsdecode is told
INSTALL_HINT = "install gpsd's gpsdecode (Debian: apt-get install gpsd-clients)"


def gpsdecode_path() -> str | None:
    """``gpsdecode`` on the PATH, or None."""
    return shutil.which("gpsdecode")


@lru_cache(maxsize=4)
def gpsdecode_version(path: str) -> str:
    """``gpsdecode 3.25``: the program and its version (``gpsdecode -V``), or ``gpsdecode`` when it does not say."""
    try:
        out = subprocess.run([path, "-V"], capture_output=True, timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return "gpsdecode"
    text = (out.stdout or out.stderr).decode("utf-8", "replace").split()
    version = next((w for w in text if w[:1].isdigit()), "")
    return f"gpsdecode {version}".strip()


class DecodedStream(io.RawIOBase):
    """``gpsdecode``'s JSON reports of the bytes of ``source`` (a binary stream, read to its end by a feeding thread).

    At the end of the reports the feeder's error (a log that cannot be read) is raised, and a ``gpsdecode`` that
    failed is a :class:`DataError` naming the log. :meth:`close` stops both."""

    def __init__(self, source: BinaryIO, name: str, program: str):
        self.name = name
        self._stderr = tempfile.TemporaryFile()
        self._proc = subprocess.Popen([program], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr)
        self._error: BaseException | None = None
        self._feeder = threading.Thread(target=self._feed, args=(source,), daemon=True, name="gpsdecode-feed")
        self._ended = False
        self._in_bytes = self._out_bytes = 0
        self._feeder.start()

    def _feed(self, source: BinaryIO) -> None:
        stdin = self._proc.stdin
        try:
            while block := source.read(FEED_BYTES):
                self._in_bytes += len(block)
                stdin.write(block)
        except (BrokenPipeError, ValueError):  # gpsdecode stopped (or was stopped by close): nothing more to give
            pass
        except BaseException as exc:  # the log's own error (a gzip cut short): raised to the reader at the end
            self._error = exc
        finally:
            try:
                stdin.close()
            except (BrokenPipeError, OSError):
                pass

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = self._proc.stdout.readinto(buffer) or 0
        self._out_bytes += n
        if not n and not self._ended:
            self._end()
        return n

    def _end(self) -> None:
        """The reports are all read: the log's error, else gpsdecode's failure."""
        self._ended = True
        self._feeder.join()
        code = self._proc.wait()
        if self._error is not None:
            raise self._error
        if code != 0:
            self._stderr.seek(0)
            said = self._stderr.read().decode("utf-8", "replace").strip().splitlines()
            raise DataError(f"{self.name}: gpsdecode failed (exit {code}){': ' + said[0] if said else ''}")
        if self._out_bytes == 0:
            raise DataError(f"{self.name}: gpsdecode found no report in its {self._in_bytes} bytes (a binary protocol gpsd "
                            "reads only from a live receiver, such as Trimble TSIP, or no receiver log)")  # fmt: skip

    def drain(self) -> None:
        """Read the rest of the reports away (the log is then read to its end: its digest is whole)."""
        while self._proc.stdout.read(FEED_BYTES):
            pass
        if not self._ended:
            self._end()

    def close(self) -> None:
        if self.closed:
            return
        if self._proc.poll() is None:
            self._proc.kill()
        self._proc.stdout.close()
        self._feeder.join(timeout=5.0)  # (a feeder waiting on a pipe that never ends is a daemon: it dies with the process)
        self._proc.wait()
        self._stderr.close()
        super().close()


def decoded(source: BinaryIO, name: str, program: str | None) -> tuple[io.BufferedReader, DecodedStream]:
    """``program``'s (gpsdecode's) reports of ``source`` as a buffered stream (with ``peek``), and the decoder under
    it; a :class:`DataError` when there is no gpsdecode (``program`` None)."""
    if program is None:
        raise DataError(f"{name}: a binary receiver protocol that gpsd decodes (SiRF, GREIS, Oncore, …): {INSTALL_HINT}, "
                        f"or pipe its output: gpsdecode < {name} | tollcli integrity -")  # fmt: skip
    raw = DecodedStream(source, name, program)
    return io.BufferedReader(raw, buffer_size=FEED_BYTES), raw
