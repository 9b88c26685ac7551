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
