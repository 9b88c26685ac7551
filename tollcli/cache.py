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
