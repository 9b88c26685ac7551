"""``batch`` as ``process``: the same charging options, only receiver logs taken from a folder, the vehicle id
the whole file name without its log suffix, and an exit code of its own when some logs failed."""

from __future__ import annotations

import json
import shutil

from conftest import REPO, SAMPLES, run_cli

from tollcli.enforcement.locate import vehicle_from_path

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def test_batch_takes_the_charging_options_of_process_and_records_them(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", logs / "TRK-1.nmea")
    (logs / "notes.txt").write_text("driver said the A9 was busy\n")  # not a log: passed over, not a vehicle
    options = ("--tc", "2", "--n-th", "3", "--fde", "--sigma-model", "constant", "--sigma", "4")
    r = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "out"), *options)
    assert r.returncode == 0, r.stderr
    assert "passed over 1 files that are not receiver logs" in r.stderr.decode() and "notes.txt" in r.stderr.decode()
    assert sorted(p.name for p in (tmp_path / "out" / "invoices").iterdir()) == ["TRK-1"]
    invoice = json.loads((tmp_path / "out" / "invoices" / "TRK-1" / "TRK-1.json").read_text())
    p = invoice["parameters"]
    assert (p["tc_s"], p["n_th"], p["fde"], p["sigma_model"], p["sigma_m"]) == (2.0, 3, True, "constant", 4.0)
    alone = tmp_path / "alone.json"
    assert run_cli("process", str(logs / "TRK-1.nmea"), "--geo", GEO, "--tariff", TARIFF, "--vehicle", "TRK-1", *options,
                   "-o", str(alone), "-q").returncode == 0  # fmt: skip
    assert json.loads(alone.read_text())["lines"] == invoice["lines"]  # the same charges as process with the same options


def test_the_vehicle_id_keeps_the_dots_inside_the_name():
    assert vehicle_from_path("logs/ublox-zed-f9p_hpg1.11.log") == "ublox-zed-f9p_hpg1.11"
    assert vehicle_from_path("TRK-042.nmea.gz") == "TRK-042" and vehicle_from_path("pixel6.23o") == "pixel6"


def test_some_logs_failed_is_its_own_exit_code(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", logs / "good.nmea")
    (logs / "broken.nmea").write_text("$GPGGA,garbage*00\n")
    r = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "out"), "-q")
    assert r.returncode == 6 and "1 of 2 logs failed" in r.stderr.decode()
    max_bad = run_cli("process", str(logs / "broken.nmea"), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "i.json"), "-q")
    assert max_bad.returncode == 1  # unusable alone: a data error, never 6
