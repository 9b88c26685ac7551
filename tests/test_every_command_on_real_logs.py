"""Every command over every receiver log of the gpsd regression suite: a documented exit code, no traceback.

Run in-process through the CLI's entry point (the same code path as the ``tollcli`` script), so that an
exception escaping a command fails the test with its traceback instead of being hidden in a subprocess.
"""

from __future__ import annotations

import pytest

from conftest import REPO, SHARED_DATA, run_main

GPSD_LOGS = sorted((SHARED_DATA / "gpsd").glob("*.log")) if (SHARED_DATA / "gpsd").exists() else []
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
DOCUMENTED = {0, 1, 2, 3}


COMMANDS = {
    "epochs": lambda log, out: ["epochs", log, "-q", "-o", f"{out}/e.csv"],
    "epochs-satellites": lambda log, out: ["epochs", log, "-q", "-o", f"{out}/e.parquet", "--satellites", f"{out}/s.parquet"],
    "integrity": lambda log, out: ["integrity", log, "-q", "-o", f"{out}/i.csv"],
    "integrity-checks": lambda log, out: ["integrity", log, "--checks", "-q", "-o", f"{out}/c.csv"],
    "findings": lambda log, out: ["findings", log, "--geo", GEO, "-q", "-o", f"{out}/f.json"],
    "locate": lambda log, out: ["locate", log, "-q", "-o", f"{out}/l.csv"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_command_over_every_gpsd_log(tmp_path, command):
    if not GPSD_LOGS:
        pytest.skip("real data not available: ../shared/data/gpsd")
    codes = {}
    for log in GPSD_LOGS:
        code, err = run_main(*COMMANDS[command](str(log), str(tmp_path)))
        assert code in DOCUMENTED, f"{log.name}: exit {code}: {err}"
        assert "Traceback" not in err, f"{log.name}: {err}"
        if code:
            assert err.strip() and log.name in err, f"{log.name}: exit {code} without saying why: {err!r}"
        codes[code] = codes.get(code, 0) + 1
    assert codes.get(0, 0) >= 90, codes  # the logs with NMEA fixes are read


def test_process_and_verify_over_every_gpsd_log(tmp_path):
    """Every real log that gives an invoice gives it again: verify reproduces it byte for byte."""
    if not GPSD_LOGS:
        pytest.skip("real data not available: ../shared/data/gpsd")
    invoiced = 0
    for i, log in enumerate(GPSD_LOGS):
        invoice = tmp_path / f"{i}.json"
        code, err = run_main("process", str(log), "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice))
        assert code in DOCUMENTED and "Traceback" not in err, f"{log.name}: exit {code}: {err}"
        if code == 0:
            invoiced += 1
            code, err = run_main("verify", str(invoice))
            assert code == 0, f"{log.name}: verify: {err}"
    assert invoiced >= 90


#: the raw-measurement files of the shared data (phones, GSDC 2022, a u-blox RAWX log)
RAW_FILES = [SHARED_DATA / p for p in ("gsdc2022/device_gnss.csv", "android/pixel6_gnsslogger.txt",
                                       "gsdc2021/Pixel4_GnssLog.txt", "gpsd/ublox-neo-m8t.log", "gsdc2021/Pixel4_derived.csv")]  # fmt: skip


@pytest.mark.parametrize("command", [*COMMANDS, "process"])
def test_every_command_over_the_raw_measurement_files(tmp_path, command):
    """Each command on each raw file, with and without the day's navigation file: a documented exit code, no
    traceback, a reason naming the file; the GSDC 2022 file is charged and verifies."""
    present = [p for p in RAW_FILES if p.exists()]
    if not present:
        pytest.skip("real data not available: ../shared/data")
    nav = SHARED_DATA / "rinex" / "brdc1190.21n"
    build = COMMANDS.get(command) or (lambda log, out: ["process", log, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", f"{out}/inv.json"])
    for log in present:
        for extra in ([], ["--nav", str(nav)]):
            args = build(str(log), str(tmp_path))
            if extra and args[0] not in ("integrity", "process"):
                continue
            code, err = run_main(*args, *extra)
            assert code in DOCUMENTED and "Traceback" not in err, f"{log.name} {extra}: exit {code}: {err}"
            if code:
                assert err.strip() and log.name in err, f"{log.name}: exit {code} without saying why: {err!r}"
            if log.name == "device_gnss.csv" and args[0] in ("integrity", "process"):
                assert code == 0, err
            if log.name == "device_gnss.csv" and args[0] == "process":
                assert run_main("verify", f"{tmp_path}/inv.json")[0] == 0
