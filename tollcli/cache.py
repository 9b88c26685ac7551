"""Where tollcli keeps what it computed once and can reuse: compiled geo-object files, RAIM threshold tables.

``$TOLLCLI_CACHE_DIR`` (default ``$XDG_CACHE_HOME/tollcli``, else ``~/.cache/tollcli``);
``TOLLCLI_CACHE_DIR=off`` turns caching off. Every cached file is named by all of
its inputs (content hashes, parameters, library versions), written atomically with the
SHA-256 of its content, checked against it when read, and recomputed when missing,
unreadable or altered, so results never depend on it.

Nothing on disk but the inputs may decide a charge, so a cache is used only where no one
else can write: a folder owned by the user and writable by nobody else. A shared folder
(world-writable with the sticky bit, as ``/tmp`` or a ``chmod 1777`` team cache) holds one
private folder per user (``tollcli-<uid>``, mode 0700). Anything else is not used (said once
on stderr, as a :class:`CacheNotUsed` warning) and the run computes without a cache: a cache
that cannot be read or written is never an error.
"""

from __future__ import annotations

import hashlib
import os
import stat
import warnings
from pathlib import Path

#: first line of a cached array's file: the format, then the SHA-256 of the ``.npy`` bytes that follow
_MAGIC = b"tollcli-cache-1 "


class CacheNotUsed(UserWarning):
    """The cache directory (or a file in it) cannot be trusted or used: the run goes on without it."""


def _note(message: str) -> None:
    warnings.warn(message, CacheNotUsed, stacklevel=3)


#: set by :func:`without_cache` (``verify`` recomputes from the inputs alone)
_turned_off = False


class without_cache:
    """Within this block no cache is read or written (as with ``TOLLCLI_CACHE_DIR=off``)."""

    def __enter__(self):
        global _turned_off
        self._before, _turned_off = _turned_off, True
        return self

    def __exit__(self, *exc):
        global _turned_off
        _turned_off = self._before


def configured_cache_dir() -> Path | None:
    """The cache directory as configured (None when turned off), before any check of who may write it."""
    if _turned_off:
        return None
    value = os.environ.get("TOLLCLI_CACHE_DIR")
    if value and value.lower() in ("off", "0", "none"):
        return None
    return Path(value) if value else Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tollcli"


def private(st: os.stat_result) -> bool:
    """Whether a file or folder is the user's own and writable by no one else (root's are trusted too)."""
    return st.st_uid in (os.getuid(), 0) and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _shared(st: os.stat_result) -> bool:
    """A folder where anyone may create entries but only their owner may remove them (``/tmp``, ``chmod 1777``)."""
    return stat.S_ISDIR(st.st_mode) and bool(st.st_mode & stat.S_ISVTX) and bool(st.st_mode & stat.S_IWOTH)


def cache_dir() -> Path | None:
    """The cache directory to use: the configured one when it is the user's own, the user's private folder in it
    when it is a shared (sticky, world-writable) one; None when caching is off or the folder cannot be trusted
    (said once on stderr). Made (mode 0700) when missing; a folder that cannot be made is None, silently."""
    base = configured_cache_dir()
    if base is None:
        return None
    try:
        st = os.stat(base)
    except FileNotFoundError:
        try:
            base.mkdir(parents=True, mode=0o700, exist_ok=True)
            st = os.stat(base)
        except OSError:
            return None  # a cache that cannot be made: skipped
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode):
        return None
    if _shared(st):
        return _own_folder(base / f"tollcli-{os.getuid()}")
    if not private(st):
        _note(f"cache {base} not used: it is writable by other users or not yours (TOLLCLI_CACHE_DIR picks another)")
        return None
    return base


def _own_folder(folder: Path) -> Path | None:
    """``folder`` (made mode 0700 when missing) when it is a real folder of the user's, writable by no one else."""
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(folder)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or not private(st):
        _note(f"cache {folder} not used: it is not a folder of yours that only you can write")
        return None
    return folder


def trusted_folder(folder: Path) -> bool:
    """Whether a folder inside the cache may be used: a real folder (no link) of the user's, writable by no one else."""
    try:
        st = os.lstat(folder)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and private(st)


def array_digest(value) -> str:
    """SHA-256 of an array's type, shape and bytes (C order): the same for an array in memory and mapped from a file."""
    import numpy as np

    value = np.ascontiguousarray(value)
    digest = hashlib.sha256(f"{value.dtype.str}{value.shape}".encode())
    digest.update(memoryview(value).cast("B") if value.size else b"")
    return digest.hexdigest()


def cached_array(folder: str, name: str, compute, shape: tuple | None = None):
    """A numpy array kept as ``<cache>/<folder>/<name>`` (``name`` must carry every input and version).

    Read when present, of ``shape`` (when given) and matching the SHA-256 written with it; otherwise ``compute()`` is
    called and its result written atomically when the folder can be.
    """
    import io
    import tempfile

    import numpy as np

    base = cache_dir()
    path = base / folder / name if base is not None else None
    if path is not None and path.exists():
        value = _read_checked(path, shape)
        if value is not None:
            return value
    value = np.asarray(compute())
    if path is not None:
        try:
            path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
            if not trusted_folder(path.parent):
                return value
            body = io.BytesIO()
            np.save(body, value, allow_pickle=False)
            data = body.getvalue()
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
            with os.fdopen(fd, "wb") as fh:
                fh.write(_MAGIC + hashlib.sha256(data).hexdigest().encode() + b"\n" + data)
            os.replace(tmp, path)
        except OSError:
            pass
    return value


def _read_checked(path: Path, shape: tuple | None):
    """The array in a cached file when its digest and shape hold (None: recompute)."""
    import io

    import numpy as np

    try:
        if not trusted_folder(path.parent):
            _note(f"cache folder {path.parent} not used: it is not yours alone")
            return None
        if not private(os.lstat(path)):
            return _failed()
        with open(path, "rb") as fh:
            raw = fh.read(1 << 24)  # (a cached row is a few kB: a file of more is not ours)
        head, _, data = raw.partition(b"\n")
        if head != _MAGIC + hashlib.sha256(data).hexdigest().encode():
            return _failed()
        value = np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return _failed()
    if shape is not None and value.shape != shape:
        return _failed()
    return value


def _failed() -> None:
    _note("cached tables that failed their check (SHA-256, shape) were computed again")
