"""The compiled store on disk: written atomically with a manifest of digests, verified before every use.

A store folder (``<cache>/geoobjects/<SHA-256 of the file>.v<STORE_FORMAT>/``) holds one ``.npy`` per array,
``strings.json`` (ids, names, road classes, frames) and ``manifest.json``, written last: the store's format, the
SHA-256 of the geo-object file it was compiled from and, per file, the SHA-256 of its content
(:func:`tollcli.cache.array_digest` for an array: its type, shape and bytes). A store is used only when its folder
and files are the user's own and writable by no one else and every file named by the manifest has the recorded
digest; anything else (a changed byte, a truncated or swapped file, a foreign owner) is :class:`StoreRejected` and
the caller compiles again. The manifest's own SHA-256 names the store: the invoice records it beside the file's.

Writers compile into a temporary folder (``*.tmp``) that they keep locked (``flock`` on ``.writer`` inside it) and
put it in place under the cache's ``.lock``: a store that verifies is never replaced, a damaged one is set aside
(``*.old``) first, so readers never see a half-replaced folder. Temporary folders whose writer died (their lock is
free) are removed by the next compile.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import stat
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tollcli.cache import array_digest, private, trusted_folder

#: files a store may hold besides its arrays
STRINGS, MANIFEST, WRITER, VERIFIED = "strings.json", "manifest.json", ".writer", "verified"
#: a temporary folder without a writer's lock file is someone's that is just starting: left alone this long, s
YOUNG_S = 3600.0


class StoreRejected(ValueError):
    """A store folder that must not be used (the message says why)."""


def strings_bytes(strings: dict) -> bytes:
    """``strings.json``'s bytes: one encoding, so that a store compiled in memory has the same digests."""
    return json.dumps(strings, ensure_ascii=False, sort_keys=True).encode("utf-8")


def manifest_of(columns: dict, fmt: int, source_sha256: str | None) -> dict:
    """The manifest of a store's columns: its format, its source's SHA-256 and each file's digest."""
    files = {STRINGS: hashlib.sha256(strings_bytes(columns["strings"])).hexdigest()}
    for name, value in columns.items():
        if name != "strings":
            files[f"{name}.npy"] = array_digest(value)
    return {"format": fmt, "source_sha256": source_sha256, "files": dict(sorted(files.items()))}


def manifest_sha256(manifest: dict) -> str:
    """The store's name in an invoice: SHA-256 of its manifest's canonical text."""
    return hashlib.sha256(json.dumps(manifest, sort_keys=True).encode()).hexdigest()


def read_verified(folder: Path, fmt: int, source_sha256: str | None) -> tuple[dict, str]:
    """The store's columns (arrays memory-mapped, read-only) and its manifest digest; StoreRejected when the folder
    is not the user's own, its manifest is not of this format and source, or any file differs from its digest.

    Every file is hashed the first time; then the files' identities (inode, size, modification and change times)
    are kept in ``verified`` beside them, and a later run that finds them unchanged skips the hashing: a write to a
    file sets its change time (ctime), which no user can set back."""
    if not trusted_folder(folder):
        raise StoreRejected("its folder is not yours alone")
    try:
        manifest_raw = _read_private(folder / MANIFEST)
        manifest = json.loads(manifest_raw)
        files = manifest["files"]
        if manifest.get("format") != fmt or manifest.get("source_sha256") != source_sha256 or not isinstance(files, dict):
            raise StoreRejected("its manifest is of another format or file")
        if STRINGS not in files or any(not isinstance(n, str) or "/" in n or not n.endswith(".npy") for n in set(files) - {STRINGS}):
            raise StoreRejected("its manifest names files a store does not have")
        identities = _identities(folder, [MANIFEST, *sorted(files)])
        checked = _stamp(identities) == _read_stamp(folder)
        raw = _read_private(folder / STRINGS)
        if not checked and hashlib.sha256(raw).hexdigest() != files[STRINGS]:
            raise StoreRejected(f"{STRINGS} differs from its digest")
        columns: dict = {"strings": json.loads(raw)}
        for name, digest in files.items():
            if name == STRINGS:
                continue
            value = np.load(folder / name, mmap_mode="r", allow_pickle=False)
            if not checked and array_digest(value) != digest:
                raise StoreRejected(f"{name} differs from its digest")
            columns[name[: -len(".npy")]] = value
    except StoreRejected:
        raise
    except (OSError, ValueError, KeyError, TypeError, EOFError, AttributeError) as exc:
        raise StoreRejected(f"unreadable ({type(exc).__name__})") from None
    if not checked:
        _write_stamp(folder, identities)
    return columns, manifest_sha256(manifest)


def _identities(folder: Path, names: list[str]) -> list[list]:
    """Per file: its name, inode, size, modification and change times (StoreRejected: not a private regular file)."""
    out = []
    for name in names:
        st = os.lstat(folder / name)
        if not stat.S_ISREG(st.st_mode) or not private(st):
            raise StoreRejected(f"{name} is not yours alone")
        out.append([name, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns])
    return out


def _stamp(identities: list[list]) -> bytes:
    return json.dumps(identities).encode()


def _read_stamp(folder: Path) -> bytes | None:
    try:
        return _read_private(folder / VERIFIED)
    except (OSError, StoreRejected):
        return None


def _write_stamp(folder: Path, identities: list[list]) -> None:
    """Record that the files as they are now passed the check (best effort: a cache that cannot be written is fine)."""
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".verified-")
        with os.fdopen(fd, "wb") as fh:
            fh.write(_stamp(identities))
        os.replace(tmp, folder / VERIFIED)
    except OSError:
        pass


def _read_private(path: Path) -> bytes:
    st = os.lstat(path)
    if not stat.S_ISREG(st.st_mode) or not private(st):
        raise StoreRejected(f"{path.name} is not yours alone")
    with open(path, "rb") as fh:
        return fh.read()


class TempStore:
    """A temporary store folder beside the store, locked while this process writes it (its lock dies with it)."""

    def __init__(self, parent: Path):
        remove_dead_writers(parent)
        self.folder = Path(tempfile.mkdtemp(dir=parent, suffix=".tmp"))
        self._lock = os.open(self.folder / f"{WRITER}-taking", os.O_WRONLY | os.O_CREAT, 0o600)
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        os.replace(self.folder / f"{WRITER}-taking", self.folder / WRITER)  # named only once locked: never taken for a dead one

    def close(self) -> None:
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None

    def discard(self) -> None:
        self.close()
        shutil.rmtree(self.folder, ignore_errors=True)


def remove_dead_writers(parent: Path) -> None:
    """Remove the temporary and set-aside folders in ``parent`` whose writer is gone (killed mid-compile)."""
    try:
        entries = [p for p in parent.iterdir() if p.suffix in (".tmp", ".old") and p.is_dir() and not p.is_symlink()]
    except OSError:
        return
    for folder in entries:
        try:
            fd = os.open(folder / WRITER, os.O_RDONLY)
        except FileNotFoundError:  # no lock file: a writer just starting, or a folder set aside and not yet removed
            try:
                stale = time.time() - os.lstat(folder).st_mtime > YOUNG_S
                if stale or (folder.suffix == ".old" and _cache_lock_free(parent)):
                    shutil.rmtree(folder, ignore_errors=True)
            except OSError:
                pass
            continue
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            shutil.rmtree(folder, ignore_errors=True)  # its writer is gone
        except OSError:
            pass  # its writer is alive
        finally:
            os.close(fd)


def _cache_lock_free(parent: Path) -> bool:
    """Whether no writer holds the cache's lock now (none is setting a store aside): taken and released at once."""
    try:
        with _cache_lock(parent, wait=False):
            return True
    except OSError:
        return False


@contextmanager
def _cache_lock(parent: Path, wait: bool = True):
    """The cache's lock (``<parent>/.lock``): held while a store is put in place or set aside."""
    fd = os.open(parent / ".lock", os.O_WRONLY | os.O_CREAT, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        yield
    finally:
        os.close(fd)


def put_in_place(temp: TempStore, folder: Path, columns: dict, fmt: int, source_sha256: str | None) -> tuple[Path, str] | None:
    """Finish the store in ``temp`` (every array written, ``strings.json``, then ``manifest.json``) and rename it to
    ``folder``, unless a store that verifies is already there (kept: another process wrote it). Returns the folder
    and the manifest digest, or None when the cache cannot be written (it is then skipped)."""
    tmp = temp.folder
    try:
        for name, value in columns.items():
            if name == "strings":
                (tmp / STRINGS).write_bytes(strings_bytes(value))
            elif not (isinstance(value, np.memmap) and Path(value.filename).parent == tmp):  # not already there
                np.save(tmp / f"{name}.npy", np.ascontiguousarray(value), allow_pickle=False)
        manifest = manifest_of(columns, fmt, source_sha256)
        (tmp / MANIFEST).write_text(json.dumps(manifest, sort_keys=True), encoding="utf-8")
        for entry in tmp.iterdir():
            entry.chmod(0o600 if entry.name == WRITER else 0o644)
        with _cache_lock(folder.parent):
            if folder.exists() or folder.is_symlink():
                try:
                    _, digest = read_verified(folder, fmt, source_sha256)
                    temp.discard()
                    return folder, digest  # another process's good store: never replaced
                except StoreRejected:
                    aside = Path(tempfile.mkdtemp(dir=folder.parent, suffix=".old"))
                    os.replace(folder, aside / folder.name)  # processes that mapped its files keep them until they end
                    shutil.rmtree(aside, ignore_errors=True)
            os.replace(tmp, folder)  # (still locked: a compile cleaning up never takes it for a dead writer's)
            os.unlink(folder / WRITER)
            temp.close()
        return folder, manifest_sha256(manifest)
    except OSError:
        temp.discard()
        return None
