"""Recognition and invoices: the main job, ``tollcli process``, on the bundled network."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest
from conftest import REPO, SAMPLES, run_cli, shared

from tollcli.charging.recognition import charges, load_geoobjects, recognise, thin_independent
from tollcli.gnss.nmea_measurements import nmea_measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim
from tollcli.readers.nmea import compose, read_nmea

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
SAMPLE = str(SAMPLES / "straight-drive.nmea")


def _drive(offset_left_m: float = 0.0, rms_m=None, n: int = 180, ellipse_follows: bool = True):
    """The sample drive, moved sideways; ``rms_m(k)`` sets the GST RMS of epoch k (a fault when large).

    ``ellipse_follows``: the receiver's error ellipse grows with a large RMS (σ's = RMS / 8), as a
    receiver's a-posteriori ellipse does, so that the RMS is a plausible range RMS; False keeps the
    2–3 m ellipse beside it (the u-blox signature of an RMS field that is no range RMS).
    """
    c = math.radians(45.0 - 90.0)
    lat = 42.6987 + offset_left_m * math.cos(c) / 111_132.0
    lon = 2.8956 + offset_left_m * math.sin(c) / (111_320.0 * math.cos(math.radians(42.6987)))
    lines = list(compose.straight_drive(n, lat_deg=lat, lon_deg=lon))
    if rms_m is not None:
        out, k = [], -1
        for line in lines:
            if "GST" in line:
                k += 1
                fields = line[1:].split("*")[0].split(",")
                fields[2] = f"{rms_m(k):.2f}"
                if ellipse_follows and rms_m(k) > 10.0:
                    fields[3] = fields[6] = fields[7] = f"{rms_m(k) / 8.0:.2f}"
                line = compose.with_checksum(",".join(fields))
            out.append(line)
        lines = out
    return read_nmea(io.BytesIO(("\n".join(lines) + "\n").encode()))


def _charge(tables, tc=5.0, n_th=1):
    geo = load_geoobjects(GEO)
    meas = nmea_measurements(tables.epochs, tables.satellites)
    positions = recognise(tables.epochs, meas, geo, RaimParams("etc"), tc_s=tc, n_th=n_th)
    return positions, charges(positions, n_th)


def test_example_network_has_hal_40_from_the_free_road_80_m_away():
    geo = load_geoobjects(GEO)
    assert list(geo.ids) == ["A9-N1", "A9-N2"]
    assert geo.hal_m == pytest.approx([40.0, 40.0], abs=0.1)


def test_drive_on_the_motorway_is_charged_every_segment():
    positions, table = _charge(_drive())
    assert table["geoobject"].tolist() == ["A9-N1", "A9-N2"] and table["charged"].all()


def test_drive_on_the_parallel_free_road_is_charged_nothing():
    positions, table = _charge(_drive(offset_left_m=80.0))
    assert table.empty and positions.empty


def test_epochs_with_a_detected_fault_never_count():
    # every other epoch has a GST RMS of 80 m: the test statistic exceeds the threshold there
    positions, table = _charge(_drive(rms_m=lambda k: 80.0 if k % 2 else 2.1))
    faulty = positions["raim_status"] == "fault_detected"
    assert faulty.sum() > 50
    assert not positions.loc[faulty, "valid"].any() and not positions.loc[faulty, "independent"].any()
    assert table["charged"].all()  # the fault-free epochs still charge both segments
    _, none = _charge(_drive(rms_m=lambda k: 80.0))
    assert not none["charged"].any() and len(none) == 2  # seen, but nothing valid: not charged


def test_an_implausible_gst_rms_neither_validates_nor_faults():
    # 80 m next to a 3 × 2 m ellipse at HDOP 0.9: no range RMS (u-blox writes such values); ignored, and for the
    # rest of the log; the ellipse's bound (4.45 × 3 m = 13.4 m ≤ HAL 40 m) still validates
    positions, table = _charge(_drive(rms_m=lambda k: 80.0 if k % 2 else 2.1, ellipse_follows=False))
    assert not (positions["raim_status"] == "fault_detected").any()
    assert set(positions["integrity_source"]) <= {"gst"} and table["charged"].all()
    tables = _drive(rms_m=lambda k: 80.0 if k % 2 else 2.1, ellipse_follows=False)
    raim = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc"))
    assert raim["gst_rms_note"].tolist()[:4] == ["", "implausible", "implausible_earlier", "implausible"]
    assert raim["test_stat"].isna().iloc[1:].all() and np.allclose(raim["hpl_gst_m"], 4.4505 * 3.0, atol=1e-3)
    # the ellipse's bound alone validates (no residual test ran)
    assert (raim["residual_status"] == "").all() and set(raim["raim_status"]) == {"valid"}


def test_tc_thinning_is_exact():
    t = np.array([0, 1, 2, 4.9, 5, 5.1, 10, 14.99, 15, 100, 103, 106])
    group = np.array([0] * 9 + [1] * 3)
    valid = np.ones(t.size, dtype=bool)
    valid[4] = False  # t = 5 is not valid: the next kept one is 5.1
    keep = thin_independent(t, group, valid, 5.0)
    assert t[keep].tolist() == [0, 5.1, 14.99, 100, 106]
    assert thin_independent(t, group, np.zeros(t.size, bool), 5.0).sum() == 0
    # every kept pair in a group is at least T_c apart, and no valid time is left that could be added
    for g in (0, 1):
        kept = t[keep & (group == g)]
        assert (np.diff(kept) >= 5.0).all()


def test_n_th_and_tc_change_the_count():
    positions, table = _charge(_drive(n=30), tc=5.0, n_th=1)
    n_indep = int(table["n_independent"].iloc[0])
    assert n_indep == 6  # 30 s of fixes at 1 Hz, T_c 5 s: t = 0, 5, …, 25
    _, strict = _charge(_drive(n=30), tc=5.0, n_th=7)
    assert not strict["charged"].any()


def test_invoice_is_byte_identical_and_totals_add_up(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for out in (a, b):
        proc = run_cli("process", SAMPLE, "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "-q")
        assert proc.returncode == 0, proc.stderr.decode()
    assert a.read_bytes() == b.read_bytes()
    inv = json.loads(a.read_text())
    from decimal import Decimal

    assert Decimal(inv["total"]) == sum(Decimal(line["fee"]) for line in inv["lines"]) == Decimal("1.90")
    assert all(line["evidence"] and all(e["raim_status"] in ("valid", "excluded_valid") for e in line["evidence"]) for line in inv["lines"])
    assert len(inv["inputs"]["log_sha256"]) == 64 and inv["parameters"]["tc_s"] == 5.0
    csv = run_cli("process", SAMPLE, "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "inv.csv"), "-q")
    assert csv.returncode == 0
    import csv as csvlib

    rows = list(csvlib.DictReader((tmp_path / "inv.csv").open(newline="")))
    # one row per invoice line, each naming its vehicle and log; the total is no row (a sum of the fee column)
    assert [r["geoobject"] for r in rows] == [line["geoobject"] for line in inv["lines"]]
    assert all(r["vehicle"] == inv["vehicle"] and r["log"] == SAMPLE and r["currency"] == "EUR" for r in rows)
    assert sum(Decimal(r["fee"]) for r in rows) == Decimal(inv["total"]) and "TOTAL" not in (tmp_path / "inv.csv").read_text()
    piped = run_cli("process", SAMPLE, "--geo", GEO, "--tariff", TARIFF, "-f", "csv", "-o", "-", "-q")
    assert piped.returncode == 0 and piped.stdout.decode() == (tmp_path / "inv.csv").read_text()


def test_truck_in_the_morning_peak_pays_the_band(tmp_path):
    # 06:30 UTC on a Monday in May is 08:30 in Paris: morning peak, 3.15 × 1.25 = 3.9375 → 3.94
    log = tmp_path / "peak.nmea"
    import datetime as dt

    log.write_text("\n".join(compose.straight_drive(60, start=dt.datetime(2024, 5, 6, 6, 30, tzinfo=dt.UTC))) + "\n")
    proc = run_cli("process", str(log), "--geo", GEO, "--tariff", TARIFF, "--vehicle-class", "truck", "-o", "-", "-q")
    inv = json.loads(proc.stdout)
    assert [(line["fee"], line["band"]) for line in inv["lines"]] == [("3.94", "morning-peak")]


def test_log_outside_every_geoobject_gives_an_empty_invoice():
    log = str(shared("android", "pixel6.nmea"))
    proc = run_cli("process", log, "--geo", GEO, "--tariff", TARIFF, "-q")
    inv = json.loads(proc.stdout)
    assert proc.returncode == 0 and inv["lines"] == [] and inv["total"] == "0.00"


@pytest.mark.parametrize("which", ["geo", "tariff"])
def test_bad_inputs_are_one_line_errors_and_keep_the_old_invoice(tmp_path, which):
    bad = tmp_path / ("bad.geojson" if which == "geo" else "bad.toml")
    bad.write_text("{oops" if which == "geo" else "currency = \n")
    out = tmp_path / "invoice.json"
    out.write_text("old invoice\n")
    args = ["process", SAMPLE, "--geo", str(bad) if which == "geo" else GEO,
            "--tariff", str(bad) if which == "tariff" else TARIFF, "-o", str(out)]  # fmt: skip
    proc = run_cli(*args)
    err = proc.stderr.decode()
    assert proc.returncode == 1 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert out.read_text() == "old invoice\n" and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
