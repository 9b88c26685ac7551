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
# xdist's workers on every core: each test's logs are read on one thread, as batch's workers read theirs (a second
# thread per run would only cost CPU there); the two-thread path is tested on its own (test_prefetch.py sets it)
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) >= (os.cpu_count() or 1):
    os.environ.setdefault("TOLLCLI_READ_AHEAD", "0")
SHARED_DATA = REPO.parent / "shared" / "data"
SAMPLES = REPO / "samples"
#: when the Berlin drive (libRSF: seconds from its start, no date) is said to have started: a Tuesday noon, outside every
#: band of the example tariff (an invoice needs a clock: process --start-time)
BERLIN_START = "2019-06-04T12:00:00+02:00"


def shared(*parts: str) -> Path:
    """A path under ../shared/data; skips the test cleanly when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path} (../shared/data is absent)")
    return path


#: ``run_cli`` forks this test process — tollcli already imported — instead of starting Python afresh: the command
#: still runs in a process of its own (its exit code, its stdout and stderr apart, its working directory and
#: environment; nothing it does comes back), without paying Python's start and tollcli's imports again, about a
#: second a run on a 2-core CI machine over a thousand runs. TOLLCLI_TEST_FRESH_PROCESS=1 starts every run afresh, as
#: a user's shell does; tests of what a start imports, of signals and of concurrent runs start their own processes.
FORKED_CLI = hasattr(os, "fork") and os.environ.get("TOLLCLI_TEST_FRESH_PROCESS", "") in ("", "0")
CLI_TIMEOUT_S = 300


def run_cli(*args: str, stdin: bytes | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m tollcli ARGS`` as a user would, capturing bytes (in a forked process: :data:`FORKED_CLI`)."""
    env = dict(os.environ, NO_COLOR="1", COLUMNS="120")
    if FORKED_CLI:
        return _forked_cli(list(args), stdin, Path(cwd or REPO), env)
    return subprocess.run(
        [sys.executable, "-m", "tollcli", *args],
        input=stdin, capture_output=True, cwd=cwd or REPO, env=env, timeout=CLI_TIMEOUT_S,
    )  # fmt: skip


def _forked_cli(args: list[str], stdin: bytes | None, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    """:func:`run_cli` in a fork of this process: the child takes the pipes as its standard streams, the directory and
    environment a new process would have, forgets what this process memoised (functions' caches, the console made
    under another environment) and runs the ``tollcli`` entry point, exiting as Python would after it."""
    import selectors
    import signal
    import time

    _import_the_commands()
    cmd = [sys.executable, "-m", "tollcli", *args]
    pipes = [os.pipe() for _ in range(3)]  # stdin, stdout, stderr
    pid = os.fork()
    if pid == 0:  # the child: never returns
        _run_forked_child(args, pipes, cwd, env)
    (in_r, in_w), (out_r, out_w), (err_r, err_w) = pipes
    for fd in (in_r, out_w, err_w):
        os.close(fd)
    out, err = bytearray(), bytearray()
    deadline = time.monotonic() + CLI_TIMEOUT_S
    with selectors.DefaultSelector() as sel:
        sel.register(out_r, selectors.EVENT_READ, out)
        sel.register(err_r, selectors.EVENT_READ, err)
        pending = memoryview(stdin or b"")
        if pending:
            sel.register(in_w, selectors.EVENT_WRITE)
        else:
            os.close(in_w)
        while len(sel.get_map()):
            ready = sel.select(timeout=max(deadline - time.monotonic(), 0.0))
            if not ready:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                for key in list(sel.get_map().values()):
                    os.close(key.fd)
                raise subprocess.TimeoutExpired(cmd, CLI_TIMEOUT_S, bytes(out), bytes(err))
            for key, _ in ready:
                if key.fd == in_w:
                    try:
                        pending = pending[os.write(in_w, pending[:65536]) :]
                    except BrokenPipeError:
                        pending = pending[:0]
                    if not pending:
                        sel.unregister(in_w)
                        os.close(in_w)
                    continue
                chunk = os.read(key.fd, 1 << 16)
                if chunk:
                    key.data.extend(chunk)
                else:
                    sel.unregister(key.fd)
                    os.close(key.fd)
    _, status = os.waitpid(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    return subprocess.CompletedProcess(cmd, code, bytes(out), bytes(err))


_IMPORTED: list[bool] = []


def _import_the_commands() -> None:
    """Every command's module and the libraries they import when they run, once in this process: each fork has them."""
    if _IMPORTED:
        return
    import importlib

    from tollcli.cli.app import COMMANDS

    for module in [m for m, _ in COMMANDS.values()] + ["tollcli.job.pipeline", "tollcli.job.log_integrity", "pyarrow.parquet",
                                                         "scipy.special", "scipy.stats", "shapely", "pyproj"]:  # fmt: skip
        with contextlib.suppress(ImportError):
            importlib.import_module(module)
    _IMPORTED.append(True)


def _run_forked_child(args: list[str], pipes, cwd: Path, env: dict) -> None:
    import functools
    import importlib
    import traceback

    import gc

    # what the parent left for the collector is not the child's to collect: a finalizer may wait for a thread that was
    # not forked (libosmium's reader, after a test read an OpenStreetMap file in this worker: the child's first
    # collection then hung until the timeout, 5 minutes of CI; tests/test_osm_network.py then test_policies.py showed it)
    gc.freeze()
    code = 1
    try:
        (in_r, in_w), (out_r, out_w), (err_r, err_w) = pipes
        for fd, target in ((in_r, 0), (out_w, 1), (err_w, 2)):
            os.dup2(fd, target)
        for fd in {in_r, in_w, out_r, out_w, err_r, err_w} - {0, 1, 2}:
            os.close(fd)
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(env)
        streams = (sys.__stdin__, sys.__stdout__, sys.__stderr__)
        sys.stdin, sys.stdout, sys.stderr = (
            io.TextIOWrapper(io.FileIO(fd, mode, closefd=False), encoding=getattr(old, "encoding", None) or "utf-8",
                             errors=getattr(old, "errors", None) or "strict", line_buffering=fd == 2)
            for fd, mode, old in zip((0, 1, 2), ("rb", "wb", "wb"), streams)
        )  # fmt: skip
        for name, module in list(sys.modules.items()):  # what a new process would not remember
            if name.startswith("tollcli") and module is not None:
                for value in list(vars(module).values()):
                    if isinstance(value, functools._lru_cache_wrapper):
                        value.cache_clear()
        if "tollcli.cli.console" in sys.modules:  # its console was made under this process's environment
            importlib.reload(sys.modules["tollcli.cli.console"])
        sys.argv = [str(REPO / "tollcli" / "__main__.py"), *args]
        from tollcli.cli.main import main

        try:
            main(args)
            code = 0
        except SystemExit as exc:
            if exc.code is None or isinstance(exc.code, int):
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
                code = 1
        except BaseException:  # noqa: BLE001 - as Python prints an uncaught exception and exits 1
            traceback.print_exc()
            code = 1
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
    finally:
        os._exit(code)


def built_geoobjects(roads: Path, geo: Path, *extra: str) -> Path:
    """``tollcli geoobjects build ROADS -o GEO`` as a user runs it (the test fails with its stderr otherwise)."""
    r = run_cli("geoobjects", "build", str(roads), "-o", str(geo), "-q", *extra)
    assert r.returncode == 0, r.stderr
    return geo


def roads_along_the_berlin_drive(tmp_path: Path) -> Path:
    """Geo-objects (built by the product) of 500 m motorways laid along the Berlin drive's own snapshot track."""
    import json

    from tollcli.geoobjects.build import build_geoobjects
    from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
    from tollcli.gnss.sigma_models import NominalModel

    epochs, _ = pseudorange_epochs(str(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt")), "librsf", None, "nominal", 5.0,
                                   NominalModel())  # fmt: skip
    lon_lat = epochs[["lon_deg", "lat_deg"]].dropna().to_numpy()[::20]
    features = [{"type": "Feature", "properties": {"id": f"B{k}", "road_class": "motorway", "tolled": True},
                 "geometry": {"type": "LineString", "coordinates": lon_lat[k * 4 : k * 4 + 5].tolist()}}
                for k in range(len(lon_lat) // 4)]  # fmt: skip
    (tmp_path / "roads.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    geo = tmp_path / "geo.geojson"
    geo.write_text(json.dumps(build_geoobjects(str(tmp_path / "roads.geojson"), hal_min_m=5.0)))  # HAL down to 5 m where asked
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


# ---- tests that need ../shared/data: counted aloud, and failures where the data is required -------------------------
#: set (CI sets it when ../shared/data is beside the checkout): a test skipped for want of shared data fails instead
REQUIRE_DATA = os.environ.get("TOLLCLI_REQUIRE_DATA", "") not in ("", "0")
_DATA_SKIPS: list[str] = []


def _is_data_skip(report) -> bool:
    if not report.skipped or not isinstance(report.longrepr, tuple):
        return False
    return "shared" in str(report.longrepr[2]).lower()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if REQUIRE_DATA and _is_data_skip(report):
        report.outcome = "failed"
        report.longrepr = f"TOLLCLI_REQUIRE_DATA is set and this test found no shared data: {report.longrepr[2]}"


def pytest_runtest_logreport(report):
    if _is_data_skip(report):
        _DATA_SKIPS.append(report.nodeid)


def pytest_terminal_summary(terminalreporter):
    if _DATA_SKIPS:
        files = sorted({nodeid.split("::")[0] for nodeid in _DATA_SKIPS})
        terminalreporter.write_sep("!", f"{len(_DATA_SKIPS)} tests in {len(files)} files did NOT run: ../shared/data is absent "
                                        f"(real receiver logs); they prove nothing here", red=True)  # fmt: skip
        terminalreporter.write_line("  " + ", ".join(files))
