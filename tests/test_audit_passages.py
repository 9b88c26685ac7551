"""Audit by passage: a road driven k times is k passages; a duplicated line is an overcharge; the money of a
missed passage comes from the invoice's own tariff, or is said to be unknown (never priced at 0)."""

from __future__ import annotations

import json
import shutil
from decimal import Decimal

import pandas as pd
import pytest
from conftest import REPO, run_cli

from tollcli.charging.audit import audit_with_truth, false_charge_bound, risk_report
from tollcli.charging.recognition import load_geoobjects
from tollcli.charging.truth_passages import truth_passages

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    """The A9 (north then south carriageway) driven k = 1, 2, 3 times, simulated fault-free, and its invoice."""
    out = {}
    for k in (1, 2, 3):
        folder = tmp_path_factory.mktemp(f"k{k}")
        sim = run_cli("simulate", "--route", ROADS, "--via", ",".join(["A9-N1", "A9-N2"] * k), "--geo", GEO, "--env", "rural",
                      "--seed", str(k), "-o", str(folder / "sim"), "-q")  # fmt: skip
        assert sim.returncode == 0, sim.stderr
        proc = run_cli("process", str(folder / "sim" / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "-o",
                       str(folder / "inv.json"), "-q")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        out[k] = folder
    return out


def _audit(*args: str) -> dict:
    proc = run_cli("audit", *args, "-o", "-", "-q")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_a_trip_driven_k_times_and_charged_correctly_audits_to_no_error(drives, k):
    folder = drives[k]
    invoice = json.loads((folder / "inv.json").read_text())
    assert len(invoice["lines"]) == 2 * k  # the recognition charged each passage
    report = _audit(str(folder / "inv.json"), "--truth", str(folder / "sim" / "truth.csv"), "--geo", GEO)
    run = report["invoices"][0]
    assert report["passages_driven"] == 2 * k and (report["missed_recognitions"], report["false_recognitions"]) == (0, 0)
    assert run["true_total"] == invoice["total"] and run["error_pct"] == 0.0 and report["share_within"] == 1.0


def test_a_duplicated_invoice_line_is_an_overcharge_and_a_dropped_one_an_undercharge(drives):
    folder = drives[2]
    invoice = json.loads((folder / "inv.json").read_text())
    truth = truth_passages(str(folder / "sim" / "truth.csv"), load_geoobjects(GEO))
    doubled = {**invoice, "lines": [*invoice["lines"], invoice["lines"][1]],
               "total": str(Decimal(invoice["total"]) + Decimal(invoice["lines"][1]["fee"]))}  # fmt: skip
    report = audit_with_truth([doubled], truth, {}, 1.0)
    run = report["invoices"][0]
    assert report["false_recognitions"] == 1 and run["overcharged"] == [invoice["lines"][1]["geoobject"]]
    assert run["money_over"] == invoice["lines"][1]["fee"] and run["error_pct"] > 1.0 and report["share_within"] == 0.0
    dropped = {**invoice, "lines": invoice["lines"][1:], "total": str(Decimal(invoice["total"]) - Decimal(invoice["lines"][0]["fee"]))}
    report = audit_with_truth([dropped], truth, {}, 1.0)
    run = report["invoices"][0]
    assert report["missed_recognitions"] == 1 and run["undercharged_entry_utc"] == [invoice["lines"][0]["entry_utc"]]
    # the passage no line charged has no fee to borrow when nothing prices it: unknown, not 0
    assert run["money_under"] is None and run["true_total"] is None and report["share_within"] is None


def test_the_audit_total_is_the_same_with_and_without_tariff_when_the_invoice_has_it_beside(drives, tmp_path):
    folder = drives[2]
    invoice = json.loads((folder / "inv.json").read_text())
    missed = invoice["lines"][1]
    invoice["lines"] = [line for line in invoice["lines"] if line is not missed]
    invoice["total"] = str(Decimal(invoice["total"]) - Decimal(missed["fee"]))
    invoice["inputs"] = {**invoice["inputs"], "tariff": "tariffs/tariff.toml", "geoobjects": "geo/geo.geojson"}  # an auditor's copy
    (tmp_path / "inv.json").write_text(json.dumps(invoice))
    shutil.copy(TARIFF, tmp_path / "tariff.toml")
    shutil.copy(GEO, tmp_path / "geo.geojson")
    truth = str(folder / "sim" / "truth.csv")
    beside = _audit(str(tmp_path / "inv.json"), "--truth", truth, "--geo", GEO)
    given = _audit(str(tmp_path / "inv.json"), "--truth", truth, "--geo", GEO, "--tariff", TARIFF)
    for report in (beside, given):
        run = report["invoices"][0]
        assert run["undercharged"] == [missed["geoobject"]] and run["money_under"] == missed["fee"]
        assert Decimal(run["true_total"]) == Decimal(invoice["total"]) + Decimal(missed["fee"]) and report["share_within"] == 0.0
    (tmp_path / "tariff.toml").unlink()  # the tariff is gone: the money is unknown, and the summary says so
    proc = run_cli("audit", str(tmp_path / "inv.json"), "--truth", truth, "--geo", GEO, "-o", "-")
    gone = json.loads(proc.stdout)
    assert gone["invoices"][0]["money_under"] is None and gone["share_within"] is None
    assert "money unknown" in proc.stderr.decode() and "within" not in proc.stderr.decode().split(";")[-1]


def test_a_gsdc_ground_truth_and_a_batch_folder_are_read(drives, tmp_path):
    folder = drives[1]
    truth = pd.read_csv(folder / "sim" / "truth.csv")
    gsdc = pd.DataFrame({"MessageType": "Fix", "Provider": "GT", "LatitudeDegrees": truth["lat_deg"],
                         "LongitudeDegrees": truth["lon_deg"], "AltitudeMeters": truth["height_m"],
                         "UnixTimeMillis": (pd.to_datetime(truth["time_utc"]) - pd.Timestamp(0, tz="UTC")) // pd.Timedelta(milliseconds=1)})  # fmt: skip
    gsdc.to_csv(tmp_path / "ground_truth.csv", index=False)
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(folder / "sim" / "drive.nmea", logs / "TRK-1.nmea")
    assert run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "out"), "-q").returncode == 0
    report = _audit(str(tmp_path / "out"), "--truth", str(tmp_path / "ground_truth.csv"), "--geo", GEO)
    assert report["runs"] == 1 and report["passages_driven"] == 2 and report["missed_recognitions"] == 0
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    err = run_cli("audit", str(folder / "inv.json"), "--truth", str(bad), "--geo", GEO).stderr.decode()
    assert "LatitudeDegrees".lower() in err.lower() and "lat_deg" in err  # names the columns it accepts


def test_the_false_charge_bound_falls_with_the_evidence():
    line = {"geoobject": "A", "fee": "1.00", "entry_utc": "2026-03-02T08:00:00Z"}

    def bound(vouched: dict, spacing_s: float = 30.0, tc_s: float = 5.0) -> float:
        evidence = [{"time_utc": f"2026-03-02T08:{int(i * spacing_s) // 60:02d}:{int(i * spacing_s) % 60:02d}Z",
                     "integrity_source": source} for source, k in vouched.items() for i in range(k)]  # fmt: skip
        evidence.sort(key=lambda e: e["time_utc"])
        n = sum(vouched.values())
        inv = {"vehicle": "v", "total": "1.00", "lines": [{**line, "n_valid_independent": n, "vouched_by": vouched, "evidence": evidence}],
               "not_charged": [], "parameters": {"p_md": 5e-5, "n_th": 1, "tc_s": tc_s}}  # fmt: skip
        return risk_report([inv], {})["charges"][0]["p_false_bound"]

    assert bound({"grs": 22}) < bound({"grs": 2}) == pytest.approx(2.5e-9)
    assert bound({"gst": 3}) == 1.0
    # positions 5 s apart (T_c) share their errors: only those 30 s apart count — 22 over 105 s are 4
    assert bound({"grs": 22}, spacing_s=5.0) == pytest.approx(false_charge_bound(4, 5e-5))
    assert bound({"grs": 22}, spacing_s=5.0, tc_s=60.0) == pytest.approx(false_charge_bound(2, 5e-5))
    assert "P_MD ** n_independent" in risk_report([], {})["p_false_bound_meaning"]
