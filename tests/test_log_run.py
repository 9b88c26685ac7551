"""One run over a log: opened once (strace), hashed as it is read, its kind from its head, stdin like a file.

Before: ``process`` opened the OSNMA recording 7 times (4 whole passes), ``verify`` 8, ``findings`` 7; the invoice's
``log_sha256`` came from another read than the bytes charged, and OSNMA could not be read from stdin.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import shutil
import subprocess
import sys

import pytest
from conftest import REPO, SAMPLES, run_cli, shared

from tollcli.errors import DataError, UsageError
from tollcli.io.log_run import LogRun

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
NMEA = SAMPLES / "sim" / "rural-clean" / "drive.nmea"


def test_the_digest_is_of_the_bytes_as_stored_and_the_kind_is_read_from_the_head(tmp_path):
    data = NMEA.read_bytes()
    packed = tmp_path / "drive.nmea.gz"
    packed.write_bytes(gzip.compress(data, mtime=0))
    for path, stored in ((NMEA, data), (packed, packed.read_bytes())):
        with LogRun(str(path)) as run:
            assert run.kind == "nmea"
            assert run.stream().read() == data  # gunzipped for the readers
            assert run.sha256 == hashlib.sha256(stored).hexdigest()  # what sha256sum says of the file
    with LogRun(str(packed)) as run:
        copy = run.replay_path()
        assert open(copy, "rb").read() == data and run.source() == copy
        assert run.sha256 == hashlib.sha256(packed.read_bytes()).hexdigest()
    assert not (tmp_path / copy).exists()  # the replay is the run's: removed with it


def test_a_reader_that_stops_early_still_gets_the_whole_files_digest():
    with LogRun(str(NMEA)) as run:
        run.stream().read(100)
        assert run.sha256 == hashlib.sha256(NMEA.read_bytes()).hexdigest()


def test_the_log_is_read_once():
    with LogRun(str(NMEA)) as run:
        run.stream()
        with pytest.raises(RuntimeError):
            run.stream()
        with pytest.raises(RuntimeError):
            run.replay_path()


def test_errors_name_the_log_not_its_copy(tmp_path):
    with pytest.raises(UsageError, match="no such file"):
        LogRun(str(tmp_path / "missing.nmea"))
    broken = tmp_path / "broken.nmea.gz"
    broken.write_bytes(gzip.compress(NMEA.read_bytes(), mtime=0)[:5000])
    with LogRun(str(broken)) as run, pytest.raises(DataError, match=r"broken\.nmea\.gz: cannot read compressed data"):
        run.replay_path()
    with LogRun(str(NMEA)) as run:
        copy = run.replay_path()
        with pytest.raises(DataError) as caught, run.named_errors():
            raise DataError(f"{copy}: line 3: not a number")
        assert str(caught.value) == f"{NMEA}: line 3: not a number"


def _opens(tmp_path, log: str, *args: str) -> int:
    """How many times a tollcli command opens ``log`` (strace -f -e trace=openat)."""
    trace = tmp_path / "trace.txt"
    r = subprocess.run(["strace", "-f", "-e", "trace=openat", "-o", str(trace), sys.executable, "-m", "tollcli", *args],
                       capture_output=True, cwd=tmp_path)  # fmt: skip
    assert r.returncode == 0, r.stderr.decode()
    return sum(1 for line in trace.read_text().splitlines() if log in line and "ENOENT" not in line)


@pytest.mark.skipif(shutil.which("strace") is None, reason="strace not installed (Debian: apt-get install strace)")
def test_every_command_that_reads_a_log_opens_it_once(tmp_path):
    recording = shared("osnma", "ublox", "current_config.ubx")
    part = tmp_path / "part.ubx"  # its first 400 kB (a binary log cut mid-message): the commands take a second, not three
    with open(recording, "rb") as fh:
        part.write_bytes(fh.read(400_000))
    binary = [str(shared("gpsd", "greis-binary.log"))] if shutil.which("gpsdecode") else []  # its bytes fed to gpsdecode
    for log in (str(NMEA), str(part), *binary):
        invoice = tmp_path / "inv.json"
        assert _opens(tmp_path, log, "process", log, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice)) == 1, log
        assert _opens(tmp_path, log, "verify", str(invoice), "-q") == 1, log
        assert _opens(tmp_path, log, "findings", log, "-q", "-o", str(tmp_path / "f.json")) == 1, log
        assert _opens(tmp_path, log, "integrity", log, "-q", "-o", str(tmp_path / "i.csv")) == 1, log
        assert _opens(tmp_path, log, "info", log, "--json") == 1, log
        assert _opens(tmp_path, log, "locate", log, "-q", "-o", str(tmp_path / "l.csv")) == 1, log
        assert json.loads(invoice.read_text())["inputs"]["log_sha256"] == hashlib.sha256(open(log, "rb").read()).hexdigest()
    assert _opens(tmp_path, str(recording), "osnma", str(recording), "-o", str(tmp_path / "o.csv")) == 1


def test_process_authenticates_the_osnma_recording_from_stdin(tmp_path):
    folder = shared("osnma", "ublox")
    log = folder / "current_config.ubx"
    keys = ["--osnma-merkle", str(folder / "OSNMA_MerkleTree.xml"), "--osnma-public-key", str(folder / "OSNMA_PublicKey_2.xml")]
    from_file, from_stdin = tmp_path / "file.json", tmp_path / "stdin.json"
    assert run_cli("process", str(log), "--geo", GEO, "--tariff", TARIFF, *keys, "-q", "-o", str(from_file)).returncode == 0
    r = run_cli("process", "-", "--geo", GEO, "--tariff", TARIFF, *keys, "-q", "-o", str(from_stdin), stdin=log.read_bytes())
    assert r.returncode == 0, r.stderr.decode()
    a, b = json.loads(from_file.read_text()), json.loads(from_stdin.read_text())
    assert b["navigation_authentication"] == a["navigation_authentication"]
    assert b["navigation_authentication"]["epochs"]["authenticated"] > 3000
    assert b["lines"] == a["lines"] and b["findings"] == a["findings"]


def test_info_reads_stdin_as_a_file(tmp_path):
    """``info -`` counts and reads the bytes of stdin as it does a file's."""
    from_file = run_cli("info", str(NMEA), "--json")
    from_stdin = run_cli("info", "-", "--json", stdin=NMEA.read_bytes())
    assert from_file.returncode == from_stdin.returncode == 0, from_stdin.stderr
    a, b = json.loads(from_file.stdout), json.loads(from_stdin.stdout)
    assert a.pop("file") == str(NMEA) and b.pop("file") == "-"
    assert a == b and a["epochs"] > 0 and a["messages"]
