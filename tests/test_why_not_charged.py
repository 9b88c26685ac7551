"""The user is told why a check did not check and why nothing was charged: a log shorter than the speed window, a
vehicle that did not move, a receiver without integrity output.

Before: a 5 s log was ``speed_no_data`` on every position, charged nothing, and nothing said why; then it said why
but still charged nothing — though no check had found a fault. Now the speed check vetoes only on a fault: the RAIM's
verdict stands, and the line says which checks did not check and why."""

from __future__ import annotations

import json

from conftest import REPO, SAMPLES, run_cli

from tollcli.readers.nmea.compose import straight_drive

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _process(log, tmp_path) -> tuple[dict, str]:
    out = tmp_path / "inv.json"
    r = run_cli("process", str(log), "--geo", GEO, "--tariff", TARIFF, "-o", str(out))
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text()), r.stderr.decode()


def test_a_log_shorter_than_the_speed_window_says_so(tmp_path):
    lines = (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()
    short = tmp_path / "short.nmea"
    short.write_text("\n".join(line for line in lines if line[7:13] < "080005") + "\n")  # 5 s inside the A9
    invoice, err = _process(short, tmp_path)
    line = invoice["lines"][0]
    assert invoice["total"] == "1.19" and invoice["not_charged"] == [] and set(line["statuses"]) == {"valid"}
    assert line["checks"] == {"confirmed": {}, "not_checked": {"speed_no_data": len(line["evidence"])}}
    assert all(item["confirmed_by"] == [] and item["not_checked"] == ["speed_no_data"] for item in line["evidence"])
    assert invoice["status_notes"]["speed_no_data"].startswith("log shorter than the speed window: 4 s")
    assert "the checks confirmed: speed 0" in err and len(err.strip().splitlines()) == 1


def test_a_stationary_vehicle_says_so(tmp_path):
    log = tmp_path / "parked.nmea"
    log.write_text("\n".join(straight_drive(120, speed_mps=0.0)) + "\n")  # parked on the A9 for two minutes
    invoice, err = _process(log, tmp_path)
    # parked inside the geo-object with RAIM-valid positions: it is there, and charged (a stop is no fault)
    assert invoice["total"] != "0.00" and invoice["not_charged"] == []
    checks = invoice["lines"][0]["checks"]
    assert checks["confirmed"] == {} and checks["not_checked"].get("speed_low_speed", 0) > 10
    assert "stationary" in invoice["status_notes"]["speed_low_speed"] and "RAIM's verdict stands" in invoice["status_notes"]["speed_low_speed"]


def test_a_log_without_integrity_sources_says_so_per_passage(tmp_path):
    """GGA and RMC only (as Android's GnssLogger writes them): only the model level's HDOP bound, above the HAL;
    each passage says why in those words."""
    lines = [line for line in (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()
             if line[3:6] in ("GGA", "RMC")]  # fmt: skip
    log = tmp_path / "gga-rmc.nmea"
    log.write_text("\n".join(lines) + "\n")
    invoice, err = _process(log, tmp_path)
    assert invoice["total"] == "0.00" and len(invoice["not_charged"]) == 2
    for passage in invoice["not_charged"]:
        assert passage["why"].startswith("the receiver reports no integrity output") and "unavailable:" in passage["why"]
