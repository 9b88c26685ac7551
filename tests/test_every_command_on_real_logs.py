"""Every command over every receiver log of the gpsd regression suite: a documented exit code, no traceback, and
outputs that hold what they claim (rows, statuses, findings; the fixes gpsd itself decoded).

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
        else:
            _check_output(command, log, tmp_path)
        codes[code] = codes.get(code, 0) + 1
    assert codes.get(0, 0) >= 90, codes  # the logs with NMEA fixes are read


def _check_output(command: str, log, out) -> None:
    """What each command's output must hold on a log it read (exit 0)."""
    import json

    import numpy as np
    import pandas as pd

    from tollcli.enforcement.findings import CATEGORY
    from tollcli.integrity.raim import STATUSES
    from tollcli.integrity.speed import SPEED_STATUSES

    if command.startswith("epochs"):
        table = pd.read_csv(out / "e.csv") if command == "epochs" else pd.read_parquet(out / "e.parquet")
        assert len(table) > 0 and {"time_utc", "lat_deg", "lon_deg"} <= set(table.columns), log.name
        chk = log.with_name(log.name + ".chk")
        if command == "epochs" and chk.exists():  # every fix gpsd decoded from a standard sentence, at the same place
            from gpsd_chk import gpsd_fixes, our_fixes

            table["time_utc"] = pd.to_datetime(table["time_utc"], utc=True, format="ISO8601")
            ours, theirs = our_fixes(table), gpsd_fixes(chk)
            shared_times = set(ours) & set(theirs)
            for t in shared_times:
                assert np.allclose(ours[t], theirs[t], atol=1e-6), (log.name, t, ours[t], theirs[t])
    elif command.startswith("integrity"):
        table = pd.read_csv(out / ("i.csv" if command == "integrity" else "c.csv"), low_memory=False)
        assert len(table) > 0 and set(table["raim_status"].dropna()) <= set(STATUSES), log.name
        hpl = table["hpl_m"].to_numpy(float)
        assert (hpl[np.isfinite(hpl)] >= 0).all(), log.name
        valid = table["raim_status"].isin(["valid", "excluded_valid"]).to_numpy()
        assert (table["hpl_m"].to_numpy(float)[valid] <= table["hal_m"].to_numpy(float)[valid] + 1e-9).all() or \
            set(table.loc[valid, "integrity_source"]) - {"grs", "pseudorange", "model"}, log.name  # fmt: skip
        if command == "integrity-checks":
            assert set(table["speed_status"].dropna()) <= set(SPEED_STATUSES), log.name
    elif command == "findings":
        doc = json.loads((out / "f.json").read_text())
        for f in doc["findings"]:
            assert f["kind"] in CATEGORY and f["category"] == CATEGORY[f["kind"]], (log.name, f)
            assert f["start_utc"] <= f["end_utc"] or f["kind"] == "time_jump", (log.name, f)  # time may run backwards
    elif command == "locate":
        located = pd.read_csv(out / "l.csv")  # a log without one fix locates nothing, and says so in a header-only table
        assert {"vehicle", "lat_deg", "lon_deg"} <= set(located.columns) and located["lat_deg"].between(-90, 90).all(), log.name


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
