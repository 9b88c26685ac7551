"""Settings are checked wherever they come from (options, an invoice to verify, batch): no hang, no silent default."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest

from conftest import REPO, run_cli
from tollcli.charging.invoice import invoice_json, seal
from tollcli.charging.recognition import thin_independent
from tollcli.enforcement.findings import CLASS_MAX_SPEED_MPS, FindingSettings
from tollcli.errors import UsageError

DRIVE = str(REPO / "samples" / "straight-drive.nmea")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _one_line_error(result, code: int = 2) -> str:
    err = result.stderr.decode()
    assert result.returncode == code, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("tc", ["0", "1e-12", "-5", "nan"])
def test_process_refuses_a_correlation_time_below_a_tenth_of_a_second(tc):
    start = time.monotonic()
    result = run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "--tc", tc, "-q", "-o", "-")
    _one_line_error(result)
    assert time.monotonic() - start < 60


def test_thinning_ends_whatever_the_correlation_time():
    t = np.repeat(np.arange(50.0), 2)  # duplicated times too
    group = np.zeros(t.size, dtype=np.int64)
    for tc in (0.0, 1e-12, 1.0):
        keep = thin_independent(t, group, np.ones(t.size, bool), tc)
        assert keep[0] and keep.sum() >= 50


def test_verify_of_an_invoice_with_a_bad_parameter_is_a_one_line_error(tmp_path):
    invoice = tmp_path / "invoice.json"
    assert run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice)).returncode == 0
    doc = json.loads(invoice.read_text())
    for name, value in (("tc_s", -5), ("n_th", 0), ("p_md", 1.5), ("tc_s", "5"), ("continued", ["A9-N1"]),
                        ("continued", {"A9-N1": {"log": "x", "exit_utc": "yesterday"}})):  # fmt: skip
        doc["parameters"] = {**doc["parameters"], name: value}
        bad = tmp_path / f"bad-{name}.json"
        bad.write_text(invoice_json(seal(doc)))
        assert name in _one_line_error(run_cli("verify", str(bad)))
        doc = json.loads(invoice.read_text())


@pytest.mark.parametrize("command", ["process", "findings"])
def test_an_unknown_vehicle_class_is_refused(command):
    args = ["--geo", GEO] + (["--tariff", TARIFF, "-q", "-o", "-"] if command == "process" else ["-q"])
    err = _one_line_error(run_cli(command, DRIVE, *args, "--vehicle-class", "Truck"))
    assert "Truck" in err


def test_findings_settings_of_each_class_and_of_a_given_top_speed():
    assert FindingSettings.for_class("truck").max_speed_mps == CLASS_MAX_SPEED_MPS["truck"]
    assert FindingSettings.for_class("hgv-4", max_speed_mps=25.0).max_speed_mps == 25.0
    with pytest.raises(UsageError, match="'Truck'"):
        FindingSettings.for_class("Truck")


def test_an_auditor_verifies_the_invoice_with_its_files_in_another_folder(tmp_path):
    """Invoice and inputs handed over in one folder, verified from anywhere; a re-indented copy verifies too."""
    work = tmp_path / "operator"
    (work / "logs").mkdir(parents=True)
    (work / "logs" / "drive.nmea").write_bytes((REPO / "samples" / "sim" / "rural-clean" / "drive.nmea").read_bytes())
    (work / "geo.geojson").write_bytes(open(GEO, "rb").read())
    (work / "tariff.toml").write_bytes(open(TARIFF, "rb").read())
    (work / "out").mkdir()
    made = run_cli("process", "logs/drive.nmea", "--geo", "geo.geojson", "--tariff", "tariff.toml", "-q", "-o", "out/inv.json",
                   cwd=work)  # fmt: skip
    assert made.returncode == 0, made.stderr.decode()
    handed = tmp_path / "auditor" / "case-17"
    handed.mkdir(parents=True)
    for src in ("out/inv.json", "logs/drive.nmea", "geo.geojson", "tariff.toml"):
        (handed / os.path.basename(src)).write_bytes((work / src).read_bytes())
    assert run_cli("verify", str(handed / "inv.json"), cwd=tmp_path).returncode == 0
    doc = json.loads((handed / "inv.json").read_text())
    (handed / "reindented.json").write_text(json.dumps(doc, indent=4, sort_keys=False))
    result = run_cli("verify", str(handed / "reindented.json"), cwd=tmp_path)
    assert result.returncode == 0, result.stderr.decode()
    (handed / "tariff.toml").write_text(open(TARIFF).read().replace("car = 0.95", "car = 0.96"))
    changed = run_cli("verify", str(handed / "inv.json"), cwd=tmp_path)
    assert changed.returncode == 1 and "tariff" in changed.stderr.decode() and "changed" in changed.stderr.decode()


@pytest.mark.parametrize("damage", [{"parameters": []}, {"inputs": {"log": 5}}, {"inputs": []}], ids=str)
def test_verify_of_a_hand_made_invoice_is_a_one_line_error(tmp_path, damage):
    invoice = tmp_path / "invoice.json"
    assert run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice)).returncode == 0
    doc = {**json.loads(invoice.read_text()), **damage}
    invoice.write_text(invoice_json(seal(doc)))
    result = run_cli("verify", str(invoice))
    err = result.stderr.decode()
    assert result.returncode in (1, 2) and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
