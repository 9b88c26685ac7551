"""Shared test fixtures: where the real data lives, and CLI runners (a subprocess, or in-process)."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# compiled geo-objects and threshold tables go to a fresh folder, never the user's cache
os.environ.setdefault("TOLLCLI_CACHE_DIR", tempfile.mkdtemp(prefix="tollcli-test-cache-"))
SHARED_DATA = REPO.parent / "shared" / "data"
SAMPLES = REPO / "samples"


def shared(*parts: str) -> Path:
    """A path under ../shared/data; skips the test cleanly when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path} (../shared/data is absent)")
    return path


def run_cli(*args: str, stdin: bytes | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m tollcli ARGS`` as a user would, capturing bytes."""
    env = dict(os.environ, NO_COLOR="1", COLUMNS="120")
    return subprocess.run(
        [sys.executable, "-m", "tollcli", *args],
        input=stdin, capture_output=True, cwd=cwd or REPO, env=env, timeout=300,
    )  # fmt: skip


def built_geoobjects(roads: Path, geo: Path, *extra: str) -> Path:
    """``tollcli geoobjects build ROADS -o GEO`` as a user runs it (the test fails with its stderr otherwise)."""
    r = run_cli("geoobjects", "build", str(roads), "-o", str(geo), "-q", *extra)
    assert r.returncode == 0, r.stderr
    return geo


def run_main(*args: str) -> tuple[int, str]:
    """Run the CLI's entry point in this process (the ``tollcli`` script's code path): (exit code, stderr).

    An exception escaping a command fails the test with its traceback instead of hiding in a subprocess.
    """
    from tollcli.cli.main import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main(list(args))
            code = 0
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()
