"""A batch whose disk fills or whose ``failed/`` folder cannot be written (part of issues 54 and 55): with two workers
the pool used to die (``BrokenProcessPool``, exit 5, no summary). Now the log the system refused fails with the
reason, the others are charged, the summary is written, and the batch exits 4 (a system error), every invoice left
complete."""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys

from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _logs(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "straight-drive.nmea", logs / "a.nmea")
    for name in ("rural-clean", "urban-clean", "rural-fault"):
        shutil.copy(SAMPLES / "sim" / name / "drive.nmea", logs / f"{name}.nmea")
    return logs


def _complete_invoices(out) -> list[str]:
    names = []
    for path in sorted((out / "invoices").rglob("*.json")):
        json.loads(path.read_text())  # complete JSON, or this fails
        names.append(path.stem)
    assert not list(out.rglob("*.tmp")) and not list(out.rglob(".*.tmp"))  # nothing half-written left
    return names


def test_a_disk_that_fills_fails_those_logs_and_keeps_the_pool(tmp_path):
    """Files limited to 60 kB (RLIMIT_FSIZE: a write beyond fails with "File too large", as on a full disk): the
    straight drive's epoch table (53 kB) fits, the simulated drives' (82 kB) do not."""

    def small_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))

    out = tmp_path / "out"
    env = dict(os.environ, TOLLCLI_CACHE_DIR="off")  # the geo-object store's own writes on a full disk: issue 50's
    done = subprocess.run([sys.executable, "-m", "tollcli", "batch", str(_logs(tmp_path)), "--geo", GEO, "--tariff", TARIFF,
                           "-o", str(out), "--workers", "2", "-q"], preexec_fn=small_files, capture_output=True, env=env)  # fmt: skip
    err = done.stderr.decode()
    assert done.returncode == 4, err
    assert len(err.strip().splitlines()) == 1 and "File too large" in err and "internal error" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["done"] == 1 and summary["failed"] == 3
    assert all(o.get("system_error") for o in summary["outcomes"] if o["status"] == "failed")
    assert _complete_invoices(out) == ["a"]


def test_a_failed_folder_that_is_a_dangling_link_is_a_system_error(tmp_path):
    """``failed/`` a dangling symbolic link, one log bad: the others charged, the bad one reported in the summary and on
    stderr, exit 4 (with two workers: ``BrokenProcessPool``, exit 5)."""
    logs = _logs(tmp_path)
    (logs / "bad.nmea").write_text("not a log\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "failed").symlink_to(tmp_path / "nowhere" / "failed")
    done = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "--workers", "2", "-q")
    err = done.stderr.decode()
    assert done.returncode == 4, err
    assert "bad.nmea" in err and "could not be written" in err and len(err.strip().splitlines()) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["done"] == 4 and summary["failed"] == 1
    assert sorted(_complete_invoices(out)) == ["a", "rural-clean", "rural-fault", "urban-clean"]
