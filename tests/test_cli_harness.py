"""The tests' way of running ``tollcli`` as a user would (``conftest.run_cli``): a fork of the test process must give
what a new Python gives — the same exit code, stdout and stderr bytes — for output to a pipe, input from one, a
usage error, a data error and a command that writes files; and nothing it does may come back to the test process."""

import os

import pytest

import conftest
from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
LOG = str(SAMPLES / "straight-drive.nmea")

CASES = {
    "version": (["--version"], None),
    "invoice on stdout": (["process", LOG, "--geo", GEO, "--tariff", TARIFF], None),
    "log on stdin": (["epochs", "-", "-f", "csv", "-q"], (SAMPLES / "straight-drive.nmea").read_bytes()),
    "usage error": (["process", LOG, "--geo", GEO, "--tariff", TARIFF, "--p-md", "2"], None),
    "data error": (["epochs", "-", "--strict", "-q", "-f", "csv"], b"$GPGGA,not a sentence*00\n"),
    "missing file": (["info", "no-such.nmea"], None),
}


@pytest.mark.skipif(not conftest.FORKED_CLI, reason="run_cli starts a new Python here (TOLLCLI_TEST_FRESH_PROCESS or no fork)")
@pytest.mark.parametrize("case", list(CASES))
def test_a_forked_run_gives_what_a_new_python_gives(monkeypatch, case):
    args, stdin = CASES[case]
    forked = run_cli(*args, stdin=stdin)
    monkeypatch.setattr(conftest, "FORKED_CLI", False)
    fresh = run_cli(*args, stdin=stdin)
    assert (forked.returncode, forked.stdout, forked.stderr) == (fresh.returncode, fresh.stdout, fresh.stderr)
    assert case not in ("usage error", "data error", "missing file") or forked.returncode in (1, 2)


@pytest.mark.skipif(not conftest.FORKED_CLI, reason="run_cli starts a new Python here")
def test_nothing_a_forked_run_does_comes_back(tmp_path):
    before = (os.getcwd(), dict(os.environ))
    out = tmp_path / "invoice.json"
    r = run_cli("process", LOG, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(out), cwd=tmp_path)
    assert r.returncode == 0 and out.exists()
    assert (os.getcwd(), dict(os.environ)) == before  # its directory and its NO_COLOR / COLUMNS stayed its own
