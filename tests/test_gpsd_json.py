"""gpsd JSON input: gpsd's own reports of the shared logs (its regression ``.chk``, ``gpspipe -w``), and
``gpsdecode`` (Debian's gpsd-clients; these tests skip without it) of the u-blox, SiRF and Trimble binary logs."""

from __future__ import annotations

import io
import json
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, SHARED_DATA, run_cli, shared
from gpsd_chk import rollover_key

from tollcli.integrity.raim import RaimParams
from tollcli.io.sources import format_of_head
from tollcli.job.log_integrity import iter_integrity
from tollcli.readers.gpsd_json import iter_gpsd_json_tables
from tollcli.readers.nmea import ReadStats

GPSD = SHARED_DATA / "gpsd"
GPSDECODE = shutil.which("gpsdecode")
#: logs whose gpsdecode output has no TPV fix gpsd's daemon gives, and why (gpsdecode decodes packet by packet,
#: without the daemon's session: TSIP's position packets and a timing receiver's survey need that state)
GPSDECODE_WITHOUT_FIXES = {
    "trimble-*.log": "gpsdecode 3.22 decodes Trimble TSIP satellites (SKY) but no position: read gpsd's JSON (gpspipe -w)",
    "u-blox-m8t-time.log": "a timing receiver in time mode: gpsdecode reports mode 0; gpsd's daemon gives its surveyed position",
}
#: automotive logs whose high-rate HNR-PVT fixes gpsd reports beside the 1 Hz NAV ones
HIGH_RATE = {"ublox-neo-m8l.log", "ublox-neo-m8u-hnr.log"}


def gpsd_tpv_fixes(text: str) -> dict[int, tuple[float, float]]:
    """rollover_key(time) → (lat, lon) of gpsd's last TPV with a 2-D/3-D fix at each time."""
    out: dict[int, tuple[float, float]] = {}
    for line in text.splitlines():
        if line.startswith('{"class":"TPV"'):
            r = json.loads(line)
            if r.get("mode", 0) >= 2 and "lat" in r and "time" in r:
                out[rollover_key(np.datetime64(r["time"].rstrip("Z"), "ms"))] = (r["lat"], r["lon"])
    return out


def our_fixes(source) -> dict[int, tuple[float, float]]:
    chunks = list(iter_gpsd_json_tables(source))
    if not chunks:
        return {}
    e = pd.concat([c.epochs for c in chunks], ignore_index=True)
    e = e[e["lat_deg"].notna() & e["time_utc"].notna()]
    times = e["time_utc"].dt.tz_convert(None).to_numpy().astype("datetime64[ms]")
    return {rollover_key(t): (a, b) for t, a, b in zip(times, e["lat_deg"], e["lon_deg"])}


def _agree(ours: dict, theirs: dict) -> tuple[float, float]:
    """(share of gpsd's fixes we have, largest position difference in degrees over them)."""
    common = set(ours) & set(theirs)
    diff = max((max(abs(ours[k][0] - theirs[k][0]), abs(ours[k][1] - theirs[k][1])) for k in common), default=0.0)
    return len(common) / max(len(theirs), 1), diff


def test_gpsd_reports_of_every_shared_log_are_read_as_gpsd_gives_them():
    """gpsd's own JSON of all 175 logs (their ``.chk``, NMEA echoed between the reports): every TPV fix is an epoch
    with gpsd's position, whatever protocol the receiver spoke (or a re-report of one, within 2 s of it)."""
    if not GPSD.exists():
        pytest.skip("real data not available: ../shared/data/gpsd")
    n_logs = 0
    for chk in sorted(GPSD.glob("*.chk")):
        text = chk.read_text(encoding="latin-1")
        theirs = gpsd_tpv_fixes(text)
        if not theirs:
            continue
        n_logs += 1
        ours = our_fixes(chk)
        share, diff = _agree(ours, theirs)
        # a fix gpsd re-reports after a later one (SiRF's messages, a clock running back) joins the epochs around it
        keys = np.array(sorted(ours))
        lost = [t for t in theirs if t not in ours and not ((keys > t) & (keys <= t + 2000)).any()]
        assert len(lost) <= max(1, 0.02 * len(theirs)) and diff < 1e-5, (chk.name, share, diff, lost[:3])
    assert n_logs >= 140


def _gpsdecode(log) -> bytes:
    with open(log, "rb") as fh:
        return subprocess.run([GPSDECODE], stdin=fh, capture_output=True, timeout=120).stdout


@pytest.mark.skipif(GPSDECODE is None, reason="gpsdecode not installed (Debian: apt-get install gpsd-clients)")
def test_gpsdecode_of_the_binary_logs_gives_gpsds_epochs():
    """u-blox, SiRF and Trimble binary logs through ``gpsdecode``: the epochs with a fix are gpsd's TPV fixes
    (its daemon's, in the ``.chk``; times compared modulo 1024 GPS weeks, which gpsd's regression run shifts), at
    the same positions; the exceptions are listed with their reason and checked to be what they say."""
    import fnmatch

    if not GPSD.exists():
        pytest.skip("real data not available: ../shared/data/gpsd")
    logs = [p for pat in ("ublox*.log", "u-blox*.log", "sirf*.log", "trimble*.log") for p in sorted(GPSD.glob(pat))]
    checked = 0
    for log in logs:
        theirs = gpsd_tpv_fixes(log.with_name(log.name + ".chk").read_text(encoding="latin-1"))
        if not theirs:
            continue
        ours = our_fixes(io.BytesIO(_gpsdecode(log)))
        share, diff = _agree(ours, theirs)
        if any(fnmatch.fnmatch(log.name, pat) for pat in GPSDECODE_WITHOUT_FIXES):
            assert not ours, log.name  # still as the exception says: no fix from gpsdecode
            continue
        if log.name in HIGH_RATE:
            share = len(set(ours) & set(theirs)) / max(len(ours), 1)  # every fix we have is one of gpsd's
            assert share >= 0.9 and diff < 1e-4, (log.name, share, diff)
        else:  # a cycle cut at the log's start or end may differ: at most two fixes or 15 % missing
            missing = len(set(theirs) - set(ours))
            assert missing <= max(2, 0.15 * len(theirs)) and diff < 1e-4, (log.name, share, diff)
        checked += 1
    assert checked >= 25


@pytest.mark.skipif(GPSDECODE is None, reason="gpsdecode not installed (Debian: apt-get install gpsd-clients)")
def test_a_sirf_log_through_gpsdecode_in_a_pipe(tmp_path):
    """``gpsdecode < sirf.log | tollcli integrity -``: stdin recognised as gpsd JSON, positions and verdicts."""
    if not GPSD.exists():
        pytest.skip("real data not available: ../shared/data/gpsd")
    data = _gpsdecode(GPSD / "sirfstarv.log")
    proc = run_cli("integrity", "-", "-o", str(tmp_path / "i.csv"), "--json", stdin=data)
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert summary["format"] == "gpsd-json" and summary["epochs"] >= 50  # 57 TPV times, a few re-reports among them
    assert set(summary["statuses"]) - {"unmonitored"}, summary


def test_malformed_reports_are_counted_and_strict_names_the_line(tmp_path):
    tpv = {"class": "TPV", "mode": 3, "time": "2024-05-06T12:00:00.000Z", "lat": 42.7, "lon": 2.9, "speed": 20.0}
    sky = {"class": "SKY", "time": "2024-05-06T12:00:00.000Z", "hdop": 0.9, "satellites": [
        {"gnssid": 0, "svid": s, "el": 20 + 10 * s, "az": 40 * s, "ss": 42, "used": True, "prRes": 0.2 * (-1) ** s}
        for s in range(1, 8)]}  # fmt: skip
    lines = ['{"class":"VERSION","release":"3.22"}', json.dumps(sky), json.dumps(tpv), '{"class":"TPV", "mode": 3, "lat"',
             "$GPGGA,not json", json.dumps({**tpv, "time": "2024-05-06T12:00:01.000Z", "lat": 42.70001})]  # fmt: skip
    log = tmp_path / "gpspipe.json"
    log.write_text("\n".join(lines) + "\n")
    assert format_of_head(log.read_bytes()) == "gpsd-json"
    stats = ReadStats()
    chunks = list(iter_gpsd_json_tables(log, stats=stats))
    e, s = chunks[0].epochs, chunks[0].satellites
    assert stats.malformed == 1 and len(e) == 2 and (s["epoch"] == 0).sum() == 7 and (s["epoch"] == 1).sum() == 7
    assert s["used"].all() and np.allclose(s.loc[s["epoch"] == 0, "residual_m"], [0.2 * (-1) ** k for k in range(1, 8)])
    assert e["fix_mode"].tolist() == [3, 3] and e["speed_mps"].tolist() == [20.0, 20.0] and e["hdop"].iloc[0] == 0.9
    table = pd.concat([c.table for c in iter_integrity(str(log), "gpsd-json", RaimParams())], ignore_index=True)
    assert (table["integrity_source"] == "grs").all()  # SKY prRes: the residual test
    proc = run_cli("integrity", str(log), "--strict", "-q", "-o", str(tmp_path / "i.csv"))
    assert proc.returncode == 1 and "gpspipe.json:4: not a gpsd JSON report" in proc.stderr.decode()


def test_a_binary_log_without_gpsdecode_is_refused_naming_the_way_to_read_it(tmp_path):
    """A SiRF binary log given to ``integrity`` on a machine without gpsdecode: a one-line error (exit 1, no
    traceback) that names the file, the package to install and the pipe that reads it."""
    import sys

    log = shared("gpsd", "sirf2.log")
    bare = tmp_path / "bin"  # a PATH with python and nothing else
    bare.mkdir()
    (bare / "python").symlink_to(sys.executable)
    proc = subprocess.run([sys.executable, "-m", "tollcli", "integrity", str(log), "-o", str(tmp_path / "e.csv"), "-q"],
                          capture_output=True, env={"PATH": str(bare), "NO_COLOR": "1"}, cwd=REPO, timeout=120)  # fmt: skip
    err = proc.stderr.decode()
    assert proc.returncode == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert f"gpsdecode < {log} | tollcli integrity -" in err and "gpsd-clients" in err and not (tmp_path / "e.csv").exists()


@pytest.mark.skipif(GPSDECODE is None, reason="gpsdecode not installed (Debian: apt-get install gpsd-clients)")
@pytest.mark.parametrize("name", ["sirf2.log", "greis-binary.log", "oncore-binary.log", "zodiac.log"])
def test_a_binary_log_is_read_through_gpsdecode_as_the_pipe_reads_it(tmp_path, name):
    """A binary log gpsd decodes, given as it is (or gzipped), gives the very table the pipe ``gpsdecode < LOG |
    tollcli integrity -`` gives, and says it was decoded (and by which version)."""
    import gzip

    log = shared("gpsd", name)
    piped = subprocess.run([GPSDECODE], stdin=log.open("rb"), capture_output=True, check=True).stdout
    via_pipe = run_cli("integrity", "-", "-o", str(tmp_path / "pipe.csv"), "-q", "--json", stdin=piped)
    direct = run_cli("integrity", str(log), "-o", str(tmp_path / "direct.csv"), "-q", "--json")
    assert via_pipe.returncode == direct.returncode == 0, direct.stderr
    assert (tmp_path / "direct.csv").read_bytes() == (tmp_path / "pipe.csv").read_bytes()
    summary = json.loads(direct.stdout)
    assert summary["decoded_by"].startswith("gpsdecode ") and summary["format"] == "gpsd-binary" and summary["epochs"] > 0
    assert "decoded_by" not in json.loads(via_pipe.stdout)
    packed = tmp_path / f"{name}.gz"
    packed.write_bytes(gzip.compress(log.read_bytes(), mtime=0))
    assert run_cli("integrity", str(packed), "-o", str(tmp_path / "gz.csv"), "-q").returncode == 0
    assert (tmp_path / "gz.csv").read_bytes() == (tmp_path / "direct.csv").read_bytes()


@pytest.mark.skipif(GPSDECODE is None, reason="gpsdecode not installed (Debian: apt-get install gpsd-clients)")
def test_a_binary_log_gpsdecode_reads_nothing_of_says_so(tmp_path):
    """Trimble TSIP logs: gpsdecode gives no report without a live receiver; a one-line error says so."""
    log = shared("gpsd", "trimble-smt-360.log")
    proc = run_cli("integrity", str(log), "-o", str(tmp_path / "e.csv"), "-q")
    err = proc.stderr.decode()
    assert proc.returncode == 1 and err.count("\n") == 1 and "gpsdecode found no report" in err, err


@pytest.mark.skipif(GPSDECODE is None, reason="gpsdecode not installed (Debian: apt-get install gpsd-clients)")
def test_an_invoice_of_a_decoded_log_records_the_decoder_and_verifies(tmp_path):
    """``process`` of a GREIS binary log: the invoice hashes the binary file (what ``sha256sum`` says), records the
    gpsdecode that read it, and ``verify`` reproduces it; an invoice claiming another gpsdecode version does not."""
    import hashlib

    from tollcli.charging.invoice import content_sha256

    log = shared("gpsd", "greis-binary.log")
    geo, tariff = str(REPO / "geoobjects" / "example-geoobjects.geojson"), str(REPO / "geoobjects" / "example-tariff.toml")
    out = tmp_path / "inv.json"
    r = run_cli("process", str(log), "--geo", geo, "--tariff", tariff, "-o", str(out), "-q")
    assert r.returncode == 0, r.stderr
    invoice = json.loads(out.read_text())
    assert invoice["inputs"]["log_sha256"] == hashlib.sha256(log.read_bytes()).hexdigest()
    assert invoice["inputs"]["log_decoded_by"].startswith("gpsdecode ")
    assert run_cli("verify", str(out), "-q").returncode == 0
    invoice["inputs"]["log_decoded_by"] = "gpsdecode 0.1"
    invoice["content_sha256"] = content_sha256(invoice)
    forged = tmp_path / "other.json"
    forged.write_text(json.dumps(invoice, sort_keys=True, indent=1))
    r = run_cli("verify", str(forged), "-q")
    assert r.returncode == 1 and b"log_decoded_by" in r.stderr, r.stderr
