"""Audit: under/overcharges against truth, rates with intervals, and the risk report."""

from __future__ import annotations

import json
from decimal import Decimal

import pytest
from conftest import run_cli
from test_process import GEO, TARIFF, _drive

from tollcli.charging.audit import audit_with_truth, driven_from_truth, risk_report
from tollcli.charging.recognition import load_geoobjects
from tollcli.stats import wilson


def _inv(lines, total, vehicle="v", not_charged=()):
    return {"vehicle": vehicle, "total": total, "lines": [{"geoobject": g, "fee": f, "n_valid_independent": 3, "entry_utc": "x"}
                                                          for g, f in lines],
            "not_charged": list(not_charged), "parameters": {"p_md": 5e-5, "n_th": 1}}  # fmt: skip


def test_wilson_known_values():
    assert wilson(0, 1) == pytest.approx((0.0, 0.7935), abs=1e-4)
    assert wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson(0, 0) == (0.0, 1.0)


def test_under_and_overcharges_per_geoobject_and_invoice():
    invoices = [
        _inv([("A", "1.00"), ("B", "2.00")], "3.00", "right"),
        _inv([("A", "1.00")], "1.00", "missed-B"),
        _inv([("A", "1.00"), ("B", "2.00"), ("X", "0.50")], "3.50", "extra-X"),
    ]
    report = audit_with_truth(invoices, {"A", "B"}, {"A": Decimal("1.00"), "B": Decimal("2.00"), "X": Decimal("0.50")}, 1.0)
    rows = {o["geoobject"]: o for o in report["geoobjects"]}
    assert (rows["A"]["undercharges"], rows["B"]["undercharges"], rows["X"]["overcharges"]) == (0, 1, 1)
    assert rows["B"]["rate"] == pytest.approx(1 / 3) and rows["B"]["rate_ci95"] == pytest.approx(wilson(1, 3))
    runs = {r["vehicle"]: r for r in report["invoices"]}
    assert runs["missed-B"]["undercharged"] == ["B"] and runs["missed-B"]["money_under"] == "2.00"
    assert runs["extra-X"]["overcharged"] == ["X"] and runs["extra-X"]["money_over"] == "0.50"
    assert report["share_within"] == pytest.approx(1 / 3)  # only the right invoice is within 1 % of 3.00
    assert (report["missed_recognitions"], report["false_recognitions"]) == (1, 1)


def test_truth_from_a_trajectory(tmp_path):
    geo = load_geoobjects(GEO)
    for offset, expected in ((0.0, {"A9-N1", "A9-N2"}), (80.0, set())):
        epochs = _drive(offset_left_m=offset).epochs
        path = tmp_path / f"truth{offset}.csv"
        epochs[["lat_deg", "lon_deg"]].to_csv(path, index=False)
        assert driven_from_truth(str(path), geo) == expected
    ids = tmp_path / "ids.txt"
    ids.write_text("# driven\nA9-N1\n")
    assert driven_from_truth(str(ids), None) == {"A9-N1"}


def test_risk_report_bounds_and_revenue_at_risk():
    seen = {"geoobject": "B", "entry_utc": "x", "n_inside": 40, "n_valid": 0, "statuses": {"fault_detected": 40}}
    report = risk_report([_inv([("A", "1.00")], "1.00", not_charged=[seen])], {"B": Decimal("2.00")})
    assert report["money_at_risk"] == "2.00" and report["revenue_at_risk"][0]["why"] == {"fault_detected": 40}
    # 3 positions vouched by a residual test, but no times to tell how far apart: they count as one, P_MD 5e-5
    assert report["charges"][0]["p_false_bound"] == pytest.approx(5e-5)
    assert report["charges"][0]["n_vouched"] == 3 and report["charges"][0]["n_independent_errors"] == 1


def test_cli_process_then_audit_the_parallel_road_drive(tmp_path):
    drive = tmp_path / "parallel.nmea"
    import math

    from tollcli.readers.nmea import compose

    c = math.radians(-45.0)
    lat = 42.6987 + 80.0 * math.cos(c) / 111_132.0
    lon = 2.8956 + 80.0 * math.sin(c) / (111_320.0 * math.cos(math.radians(42.6987)))
    drive.write_text("\n".join(compose.straight_drive(180, lat_deg=lat, lon_deg=lon)) + "\n")
    invoice = tmp_path / "inv.json"
    assert run_cli("process", str(drive), "--geo", GEO, "--tariff", TARIFF, "-o", str(invoice), "-q").returncode == 0
    truth = tmp_path / "truth.json"
    truth.write_text('["A9-N1", "A9-N2"]')  # suppose it had really driven the motorway
    proc = run_cli("audit", str(invoice), "--truth", str(truth), "--geo", GEO, "--tariff", TARIFF, "-o", "-", "-q")
    report = json.loads(proc.stdout)
    assert proc.returncode == 0 and report["missed_recognitions"] == 2
    assert report["invoices"][0]["money_under"] == "1.90" and report["share_within"] == 0.0
    trajectory = tmp_path / "truth.geojson"
    trajectory.write_text(json.dumps({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {},
        "geometry": {"type": "LineString", "coordinates": [[lon, lat], [lon + 0.02, lat + 0.016]]}}]}))  # fmt: skip
    proc = run_cli("audit", str(invoice), "--truth", str(trajectory), "--geo", GEO, "-o", "-", "-q")
    assert json.loads(proc.stdout)["missed_recognitions"] == 0  # driven on the free road: nothing was owed
    assert run_cli("audit", str(tmp_path / "none.json")).returncode == 2  # a missing file is a usage error


def test_interrupted_write_leaves_the_old_invoice(tmp_path, monkeypatch):
    import os

    from tollcli.io import writers

    out = tmp_path / "invoice.json"
    out.write_text("old\n")

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        writers.write_text_atomic(str(out), '{"total": "1.90"}\n' * 1000)
    assert out.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == ["invoice.json"]



def test_audit_refuses_an_invoice_of_another_trip(tmp_path):
    """The straight drive of 2024 against the truth of a 2026 simulated drive: an error, not '100 % correct'."""
    from conftest import REPO, run_cli

    geo = str(REPO / "geoobjects" / "example-geoobjects.geojson")
    invoice = tmp_path / "inv.json"
    assert run_cli("process", str(REPO / "samples" / "straight-drive.nmea"), "--geo", geo, "--tariff",
                   str(REPO / "geoobjects" / "example-tariff.toml"), "-q", "-o", str(invoice)).returncode == 0  # fmt: skip
    result = run_cli("audit", str(invoice), "--truth", str(REPO / "samples" / "sim" / "urban-fault" / "truth.csv"), "--geo", geo)
    err = result.stderr.decode()
    assert result.returncode == 1 and "not the same trip" in err and len(err.strip().splitlines()) == 1
    truth = tmp_path / "truth.csv"
    truth.write_text((REPO / "samples" / "sim" / "rural-clean" / "truth.csv").read_text().replace("time_utc,", "vehicle,time_utc,", 1)
                     .replace("\n2026", "\nTRK-9,2026"))  # fmt: skip
    mine = tmp_path / "mine.json"
    assert run_cli("process", str(REPO / "samples" / "sim" / "rural-clean" / "drive.nmea"), "--geo", geo, "--tariff",
                   str(REPO / "geoobjects" / "example-tariff.toml"), "--vehicle", "TRK-1", "-q", "-o", str(mine)).returncode == 0  # fmt: skip
    other = run_cli("audit", str(mine), "--truth", str(truth), "--geo", geo)
    assert other.returncode == 1 and "TRK-9" in other.stderr.decode()
