"""Reliability: verify reproduces invoices, names what changed; partial exit; kill mid-write."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from conftest import REPO, SAMPLES, run_cli

from tollcli.job.pipeline import content_sha256
from tollcli.readers.nmea import compose


@pytest.fixture
def invoiced(tmp_path):
    shutil.copy(SAMPLES / "straight-drive.nmea", tmp_path / "log.nmea")
    shutil.copy(REPO / "geoobjects" / "example-geoobjects.geojson", tmp_path / "geo.geojson")
    shutil.copy(REPO / "geoobjects" / "example-tariff.toml", tmp_path / "tariff.toml")
    proc = run_cli("process", "log.nmea", "--geo", "geo.geojson", "--tariff", "tariff.toml", "-o", "inv.json", "-q", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr.decode()
    return tmp_path


def _verify(folder):
    proc = run_cli("verify", "inv.json", cwd=folder)
    err = proc.stderr.decode().strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return proc.returncode, err


def test_verify_reproduces_the_invoice(invoiced):
    code, message = _verify(invoiced)
    assert code == 0 and "reproduced byte for byte" in message
    inv = json.loads((invoiced / "inv.json").read_text())
    assert inv["tool"].startswith("tollcli ") and inv["parameters"]["raim"] == "ss"
    assert inv["content_sha256"] == content_sha256(inv)


@pytest.mark.parametrize("name, label", [("log.nmea", "log"), ("geo.geojson", "geo-objects"), ("tariff.toml", "tariff")])
def test_verify_names_each_changed_input(invoiced, name, label):
    with open(invoiced / name, "a", encoding="utf-8") as fh:
        fh.write("\n# changed\n" if name != "geo.geojson" else "\n")
    code, message = _verify(invoiced)
    assert code == 1 and f"{label} {name} changed since the invoice was made" in message


def test_verify_catches_an_edited_invoice_and_a_missing_input(invoiced):
    inv = json.loads((invoiced / "inv.json").read_text())
    inv["total"] = "0.10"
    (invoiced / "inv.json").write_text(json.dumps(inv, indent=2, sort_keys=True) + "\n")
    assert _verify(invoiced) == (1, "tollcli: error: inv.json: invoice content was modified (content_sha256 does not match its content)")
    inv["total"] = "1.90"
    (invoiced / "inv.json").write_text(json.dumps(inv, indent=2, sort_keys=True) + "\n")
    (invoiced / "tariff.toml").unlink()
    code, message = _verify(invoiced)
    assert code == 1 and "tariff tariff.toml not found" in message


def test_verify_catches_a_result_that_does_not_follow_from_the_inputs(invoiced):
    inv = json.loads((invoiced / "inv.json").read_text())
    inv["parameters"]["tc_s"] = 10.0  # consistent hash, but the lines list T_c = 5 s evidence
    inv["content_sha256"] = content_sha256(inv)
    (invoiced / "inv.json").write_text(json.dumps(inv, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
    code, message = _verify(invoiced)
    assert code == 1 and "gives a different invoice" in message


def test_partial_exit_code_3_still_writes(tmp_path):
    out = tmp_path / "e.csv"
    proc = run_cli("epochs", str(SAMPLES / "straight-drive.nmea"), "-o", str(out), "-q", "--max-bad", "0")
    assert proc.returncode == 3 and out.exists() and "more than --max-bad 0" in proc.stderr.decode()
    assert run_cli("epochs", str(SAMPLES / "straight-drive.nmea"), "-o", str(out), "-q", "--max-bad", "1").returncode == 0


def test_killed_mid_write_leaves_the_old_output(tmp_path):
    log = tmp_path / "long.nmea"
    log.write_text("\n".join(compose.straight_drive(60_000)) + "\n")  # ≈ 34 MB, several chunks
    out = tmp_path / "epochs.parquet"
    out.write_bytes(b"old output")
    proc = subprocess.Popen([sys.executable, "-m", "tollcli", "epochs", str(log), "-o", str(out), "-q"], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    deadline = time.time() + 120
    while time.time() < deadline and not any(p.name.endswith(".tmp") for p in tmp_path.iterdir()):
        time.sleep(0.05)
    temp = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert temp, "the writer never started a temporary file"
    while time.time() < deadline and temp[0].exists() and temp[0].stat().st_size == 0:
        time.sleep(0.05)  # wait until it is really writing
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert out.read_bytes() == b"old output"  # never half a file under the real name


@pytest.mark.parametrize("key, label", [("log", "log"), ("geoobjects", "geo-objects"), ("tariff", "tariff")])
def test_verify_names_each_corrupted_recorded_hash(invoiced, key, label):
    inv = json.loads((invoiced / "inv.json").read_text())
    inv["inputs"][f"{key}_sha256"] = "0" * 64  # a recorded hash corrupted, content hash recomputed to match
    inv["content_sha256"] = content_sha256(inv)
    (invoiced / "inv.json").write_text(json.dumps(inv, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
    code, message = _verify(invoiced)
    assert code == 1 and f"{label} {inv['inputs'][key]} changed since the invoice was made" in message
    assert "recorded 000000000000" in message


def test_a_terminate_signal_waits_until_the_temporary_file_is_named():
    """``signals_held``: SIGTERM arriving while a temporary file is created is delivered only when its name is kept
    (so the writer's cleanup knows the file); outside the block it interrupts at once."""
    import subprocess
    import sys

    code = (
        "import os, signal\n"
        "from tollcli.io.writers import signals_held\n"
        "def stop(s, f):\n    raise SystemExit(143)\n"
        "signal.signal(signal.SIGTERM, stop)\n"
        "reached = []\n"
        "try:\n"
        "    with signals_held():\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        reached.append('inside')\n"
        "    reached.append('after')\n"
        "except SystemExit:\n"
        "    print(','.join(reached))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "inside", out.stderr


def test_a_terminate_signal_taken_by_another_thread_still_waits():
    """The kernel may hand a process-directed SIGTERM to any thread that does not block it (OpenBLAS, pyarrow and
    Dask start threads); Python then runs the handler in the main thread. Sent straight to another thread here, the
    signal must still wait until the block is left, and then interrupt exactly once."""
    import subprocess
    import sys

    code = (
        "import os, signal, threading\n"
        "from tollcli.io.writers import signals_held\n"
        "calls = []\n"
        "def stop(s, f):\n    calls.append(s)\n    raise SystemExit(143)\n"
        "signal.signal(signal.SIGTERM, stop)\n"
        "gate = threading.Event()\n"
        "other = threading.Thread(target=gate.wait, daemon=True)\n"
        "other.start()\n"
        "reached = []\n"
        "try:\n"
        "    with signals_held():\n"
        "        with signals_held():\n"  # nested: the outer block decides
        "            signal.pthread_kill(other.ident, signal.SIGTERM)\n"
        "            signal.pthread_kill(other.ident, signal.SIGTERM)\n"
        "            import time\n"
        "            t0 = time.monotonic()\n"
        "            while time.monotonic() - t0 < 0.5:\n"
        "                pass\n"  # half a second of bytecodes: time for a handler to run, were it not deferred (loaded machines too)
        "            reached.append('inner')\n"
        "        reached.append('outer')\n"
        "    reached.append('after')\n"
        "except SystemExit:\n"
        "    print(','.join(reached), len(calls), signal.getsignal(signal.SIGTERM) is stop)\n"
        "gate.set()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "inner,outer 1 True", out.stderr
