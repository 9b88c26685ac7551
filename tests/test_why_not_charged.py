"""The user is told why nothing was charged: a log shorter than the speed window, a vehicle that did not move.

Before: a 5 s log was ``speed_no_data`` on every position, charged nothing, and nothing said why."""

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
    assert invoice["total"] == "0.00" and set(invoice["not_charged"][0]["statuses"]) == {"speed_no_data"}
    assert invoice["status_notes"]["speed_no_data"].startswith("log shorter than the speed window: 4 s")
    assert invoice["not_charged"][0]["why"].startswith("log shorter than the speed window: 4 s")  # per passage too
    assert "log shorter than the speed window" in err and len(err.strip().splitlines()) == 1


def test_a_stationary_vehicle_says_so(tmp_path):
    log = tmp_path / "parked.nmea"
    log.write_text("\n".join(straight_drive(120, speed_mps=0.0)) + "\n")  # parked on the A9 for two minutes
    invoice, err = _process(log, tmp_path)
    assert invoice["total"] == "0.00" and "speed_low_speed" in invoice["not_charged"][0]["statuses"]
    assert "stationary" in invoice["status_notes"]["speed_low_speed"] and "stationary" in err
    assert "stationary" in invoice["not_charged"][0]["why"] and "speed_low_speed" in invoice["not_charged"][0]["why"]


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
