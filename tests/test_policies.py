"""One verdict per epoch under a named policy: a biased drive on a parallel free road, RAIM alone against all checks."""

from __future__ import annotations

import json

import pytest

from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


@pytest.fixture(scope="module")
def parallel_drive(tmp_path_factory):
    """Driving the free D900, 80 m beside the tolled A9; from t = 40 s for 150 s the receiver's fixes are
    pushed 80 m to the right — onto the A9 — by an offset no pseudorange residual shows (RAIM passes)."""
    out = tmp_path_factory.mktemp("parallel")
    result = run_cli("simulate", "--route", ROADS, "--via", "D900", "--geo", GEO, "--env", "rural", "--seed", "3",
                     "--lateral-bias", "80", "--lateral-bias-at", "40", "--lateral-bias-duration", "150", "-q", "-o", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr.decode()
    return out


def _charge_and_audit(folder, policy: str) -> tuple[dict, dict]:
    inv = folder / f"invoice-{policy}.json"
    result = run_cli("process", str(folder / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "--roads", ROADS, "--policy", policy,
                     "-q", "-o", str(inv))  # fmt: skip
    assert result.returncode == 0, result.stderr.decode()
    audit = folder / f"audit-{policy}.json"
    result = run_cli("audit", str(inv), "--truth", str(folder / "truth.csv"), "--geo", GEO, "-q", "-o", str(audit))
    assert result.returncode == 0, result.stderr.decode()
    return json.loads(inv.read_text()), json.loads(audit.read_text())


def test_map_matching_integrity_stops_what_raim_alone_charges(parallel_drive):
    assert json.loads((parallel_drive / "truth-geoobjects.json").read_text()) == []  # the A9 was never driven
    raim_inv, raim_audit = _charge_and_audit(parallel_drive, "raim")
    all_inv, all_audit = _charge_and_audit(parallel_drive, "all")
    assert raim_audit["false_recognitions"] == 2 and {ln["geoobject"] for ln in raim_inv["lines"]} == {"A9-N1", "A9-N2"}
    assert all(ln["statuses"].get("valid", 0) > 10 for ln in raim_inv["lines"])  # RAIM vouched for the biased fixes
    assert all_audit["false_recognitions"] == 0 and all_inv["lines"] == []
    # the positions were RAIM-valid, but map matching holds the road the vehicle is on (no road connects it to the
    # A9) 80 m away, beyond their bound: a fault (mm_off_road); the speed check caught the jump onto the A9 itself
    assert all(ln["statuses"].get("mm_off_road", 0) > 50 for ln in all_inv["not_charged"])
    assert all_inv["not_charged"][0]["statuses"].get("speed_inconsistent", 0) >= 5
    assert raim_inv["parameters"]["policy_used"] == "raim" and all_inv["parameters"]["policy_used"] == "all"
    assert run_cli("verify", str(parallel_drive / "invoice-all.json")).returncode == 0


def test_default_policy_is_the_strictest_the_inputs_support(tmp_path):
    drive = str(SAMPLES / "sim" / "rural-clean" / "drive.nmea")
    for extra, expected in (([], "raim+speed"), (["--roads", ROADS], "all")):
        inv = tmp_path / "inv.json"
        assert run_cli("process", drive, "--geo", GEO, "--tariff", TARIFF, *extra, "-q", "-o", str(inv)).returncode == 0
        invoice = json.loads(inv.read_text())
        assert invoice["parameters"]["policy_used"] == expected and len(invoice["lines"]) == 2
    derived = str(SAMPLES / "sim" / "rural-clean" / "drive-derived.csv")  # pseudoranges: no speed over ground
    assert run_cli("process", derived, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(inv)).returncode == 0
    assert json.loads(inv.read_text())["parameters"]["policy_used"] == "raim"
    # with a road network too: map matching has no speed or heading to match with, so the default stays RAIM
    # (before: raim+mm, every position mm_alarm, nothing charged)
    assert run_cli("process", derived, "--geo", GEO, "--tariff", TARIFF, "--roads", ROADS, "-q", "-o", str(inv)).returncode == 0
    invoice = json.loads(inv.read_text())
    assert invoice["parameters"]["policy_used"] == "raim" and len(invoice["lines"]) == 2
    bad = run_cli("process", derived, "--geo", GEO, "--tariff", TARIFF, "--roads", ROADS, "--policy", "raim+mm", "-o", str(inv))
    assert bad.returncode == 2 and b"map matching needs the speed and heading" in bad.stderr
    bad = run_cli("process", drive, "--geo", GEO, "--tariff", TARIFF, "--policy", "raim+mm", "-o", str(inv))
    assert bad.returncode == 2 and b"needs the road network (--roads)" in bad.stderr
    bad = run_cli("process", drive, "--geo", GEO, "--tariff", TARIFF, "--policy", "everything", "-o", str(inv))
    assert bad.returncode == 2 and b"'everything' is not one of 'raim', 'raim+speed', 'raim+mm', 'all'" in bad.stderr


def test_integrity_checks_columns(tmp_path):
    out = tmp_path / "checks.csv"
    # the figures below are the ETC RAIM's (the papers'): map matching uses the positions the RAIM trusts
    result = run_cli("integrity", str(SAMPLES / "sim" / "urban-fault" / "drive.nmea"), "--raim", "etc", "--roads", ROADS, "-q", "-o", str(out))
    assert result.returncode == 0, result.stderr.decode()
    import pandas as pd

    table = pd.read_csv(out)
    for col in ("speed_status", "speed_doppler_avg_mps", "speed_position_mps", "matched_road", "delta_theta_deg", "delta_d_m",
                "delta_s_kmh", "mm_integrity", "mm_level", "mm_status", "hit_m"):  # fmt: skip
        assert col in table, col
    assert set(table["matched_road"].dropna()) == {"A9-N1", "A9-N2"}  # detected faults do not drag the match onto D900
    assert (table["mm_status"] == "ok").mean() > 0.6 and (table["speed_status"] == "ok").mean() > 0.7
