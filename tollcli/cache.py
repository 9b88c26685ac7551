"""Where tollcli keeps what it computed once and can reuse: compiled geo-object files, RAIM threshold tables.

``$TOLLCLI_CACHE_DIR`` (default ``$XDG_CACHE_HOME/tollcli``, else ``~/.cache/tollcli``);
``TOLLCLI_CACHE_DIR=off`` turns caching off. Every cached file is named by all of
its inputs (content hashes, parameters, library versions), written atomically, and
recomputed when missing or unreadable, so results never depend on it.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path | None:
    """The cache directory (None when turned off)."""
    value = os.environ.get("TOLLCLI_CACHE_DIR")
    if value and value.lower() in ("off", "0", "none"):
        return None
    return Path(value) if value else Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tollcli"


def cached_array(folder: str, name: str, compute, shape: tuple | None = None):
    """A numpy array kept as ``<cache>/<folder>/<name>`` (``name`` must carry every input and version).

    Read when present and readable (and of ``shape`` when given); otherwise ``compute()`` is
    called and its result written atomically when the directory is writable.
    """
    import tempfile

    import numpy as np

    base = cache_dir()
    path = base / folder / name if base is not None else None
    if path is not None and path.exists():
        try:
            value = np.load(path, allow_pickle=False)
            if shape is None or value.shape == shape:
                return value
        except (OSError, ValueError, EOFError):
            pass
    value = np.asarray(compute())
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
            with os.fdopen(fd, "wb") as fh:
                np.save(fh, value)
            os.replace(tmp, path)
        except OSError:
            pass
    return value
