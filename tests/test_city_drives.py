"""City charging end to end on simulated drives through the example city: a weekday through the cordon (single-charge,
daily cap), the same drive on free days, a zone, roads beside a gantry, a turn before it, GNSS outages, batch days,
verify and the audit against the simulator's truth."""

import datetime as dt
import json
from pathlib import Path

import pytest
from city_drives import (
    CITY,
    GOTHENBURG,
    TO_CORDON_S,
    ZONE_TARIFF,
    day_legs,
    invoice,
    join_logs,
    leg,
    point,
    redate_nmea,
    route_leg,
)
from conftest import REPO, run_cli, run_main


@pytest.fixture(scope="module")
def weekday(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("city-day")
    legs = day_legs(folder)
    join_logs(legs, folder / "day")
    return folder


def charge(log: Path, out: Path, tariff: Path = GOTHENBURG, *extra: str) -> dict:
    code, err = run_main("process", str(log), "--geo", str(CITY), "--tariff", str(tariff), "-o", str(out), "-q", *extra)
    assert code == 0, err
    return invoice(out)


def test_a_weekday_through_the_cordon(weekday, tmp_path):
    inv = charge(weekday / "day" / "drive.nmea", tmp_path / "day.json")
    crossings = [(l["geoobject"], l["time_local"][11:16], l["fee"]) for l in inv["lines"]]
    assert crossings == [("G1", "06:34", "16"), ("G5", "06:38", "16"), ("G5", "07:20", "22"), ("G2", "08:40", "9"),
                         ("G4", "09:59", "9"), ("G6", "12:00", "9"), ("G7", "15:10", "16"), ("G8", "16:30", "22"),
                         ("G1", "17:44", "16")]  # fmt: skip
    assert [r["rule"] for r in inv["rules"]] == ["single_charge", "daily_cap"]
    assert inv["rules"][0]["said"].startswith("single-charge: 3 passages 06:34–07:20 → 22 SEK")
    assert inv["rules"][1]["said"].endswith("daily cap 60 SEK reached: -43 SEK")
    assert inv["total"] == "60" and inv["not_charged"] == []
    for line in inv["lines"]:  # each crossing: evidence on both sides, bounds clear of the line
        before, after = line["evidence"]["before"], line["evidence"]["after"]
        assert before and after and all(abs(p["distance_m"]) > p["hpl_m"] for p in before + after)
        assert {p["distance_m"] > 0 for p in before} != {p["distance_m"] > 0 for p in after}
    code, err = run_main("audit", str(tmp_path / "day.json"), "--truth", str(weekday / "day" / "truth.csv"), "-o", str(tmp_path / "a.json"), "-q")
    assert code == 0, err
    report = json.loads((tmp_path / "a.json").read_text())
    assert (report["crossings_driven"], report["missed"], report["false"]) == (9, [], [])
    assert (report["truth_total"], report["invoiced_total"], report["undercharge"], report["overcharge"]) == ("60", "60", "0", "0")
    assert report["rules"] == {"daily_cap": {"invoices": "-43", "truth": "-43"}, "single_charge": {"invoices": "-32", "truth": "-32"}}
    code, err = run_main("verify", str(tmp_path / "day.json"))
    assert code == 0, err


@pytest.mark.parametrize("day, why", [(dt.date(2026, 3, 7), "free weekday (sat)"), (dt.date(2026, 4, 3), "public holiday"),
                                      (dt.date(2026, 4, 2), "day before a public holiday"), (dt.date(2026, 7, 7), "free month (july)")])  # fmt: skip
def test_the_same_drive_on_a_free_day_charges_nothing(weekday, tmp_path, day, why):
    log = tmp_path / "drive.nmea"
    log.write_text(redate_nmea((weekday / "day" / "drive.nmea").read_text(), day))
    inv = charge(log, tmp_path / "inv.json")
    assert len(inv["lines"]) + len(inv["not_charged"]) == 9 and inv["total"] == "0"  # (in summer time 17:44 CET is 18:44)
    assert inv["rules"][0]["rule"] == "free_day" and why in inv["rules"][0]["said"] and inv["days"][0]["free"] == why
    assert all(line["charged"] == "0" for line in inv["lines"])


def test_a_day_split_over_logs_in_batch_is_charged_as_one_day(weekday, tmp_path):
    logs = sorted(str(p / "drive.nmea") for p in weekday.glob("leg*"))
    code, err = run_main("batch", *logs, "--geo", str(CITY), "--tariff", str(GOTHENBURG), "--vehicle", "ABC123", "-o", str(tmp_path / "out"), "-q")
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    days = json.loads((tmp_path / "out" / "city-days.json").read_text())
    assert summary["totals"] == {"SEK": "60"}  # as the day's one log: the cap and the single-charge window across logs
    assert int(summary["invoice_totals"]["SEK"]) > 60  # each log alone knows nothing of the others
    vehicle = days["vehicles"]["ABC123"]
    assert [r["rule"] for r in vehicle["rules"]] == ["single_charge", "daily_cap"] and vehicle["total"] == "60"


def test_a_road_beside_a_gantry_and_a_turn_before_it_charge_nothing(tmp_path):
    start = dt.datetime(2026, 3, 3, 9, 0, tzinfo=dt.UTC)
    # P3 runs parallel to R3 30 m away, across G3's extended line; C3 runs parallel to G3's line 30 m outside it
    along_p3 = route_leg(tmp_path / "p3", [point(90.0, 1200.0, 30.0), point(90.0, 1900.0, 30.0)], start, seed=7, env="rural")
    along_c3 = route_leg(tmp_path / "c3", [point(90.0, 1530.0, -300.0), point(90.0, 1530.0, 300.0)], start, seed=8, env="rural")
    turn = route_leg(tmp_path / "turn", [point(0.0, 2500.0), point(0.0, 1560.0), point(0.0, 2500.0)], start, seed=9, env="rural")
    for drive in (along_p3, along_c3, turn):
        inv = charge(drive / "drive.nmea", tmp_path / f"{drive.name}.json")
        assert inv["lines"] == [] and inv["total"] == "0", drive.name
    p3 = invoice(tmp_path / "p3.json")
    assert p3["not_charged"] == []  # P3 crosses G3's line 30 m from the road: beyond the line and its HAL (9 m)
    # R3 itself: G3's HAL is 9 m (P3 bounds it), below what the receiver's bounds reach: seen, not charged, and why
    straight_in = leg(tmp_path / "in", 90.0, start, 200.0, seed=10, env="rural")
    r3 = charge(straight_in / "drive.nmea", tmp_path / "in.json")
    assert r3["lines"] == [] and [n["geoobject"] for n in r3["not_charged"]] == ["G3"]
    assert r3["not_charged"][0]["statuses"].get("unavailable", 0) > 0
    on_r1 = leg(tmp_path / "r1", 0.0, start, 200.0, seed=10, env="rural")  # the control: the same drive at G1 (HAL 50 m)
    assert [l["geoobject"] for l in charge(on_r1 / "drive.nmea", tmp_path / "r1.json")["lines"]] == ["G1"]


def test_a_zone_entered_three_times_is_charged_once_and_not_outside_its_hours(tmp_path):
    day = dt.datetime(2026, 3, 3, tzinfo=dt.UTC)
    legs = [leg(tmp_path / f"z{h}", 0.0, day.replace(hour=h), 450.0, seed=20 + h, env="rural") for h in (7, 9, 13)]
    log = join_logs(legs, tmp_path / "day")
    inv = charge(log, tmp_path / "zone.json", ZONE_TARIFF, "--vehicle-attr", "euro_class=euro6")
    assert [(l["kind"], l["rate"], l["fee"], l["charged"]) for l in inv["lines"]] == [("zone", "congestion", "150", "150"),
                                                                                       ("zone", "congestion", "150", "0"),
                                                                                       ("zone", "congestion", "150", "0")]  # fmt: skip
    assert inv["total"] == "150" and [r["rule"] for r in inv["rules"]] == ["zone_once_a_day"]
    old = charge(log, tmp_path / "old.json", ZONE_TARIFF, "--vehicle-attr", "euro_class=euro4")  # the emissions zone too, once
    assert old["total"] == "275"
    evening = leg(tmp_path / "late", 0.0, day.replace(hour=18, minute=30), 450.0, seed=30, env="rural")
    late = charge(evening / "drive.nmea", tmp_path / "late.json", ZONE_TARIFF, "--vehicle-attr", "euro_class=euro6")
    assert late["lines"] == [] and late["total"] == "0"
    assert late["not_charged"] and "outside the zone's charging hours" in late["not_charged"][0]["why"]
    code, err = run_main("audit", str(tmp_path / "zone.json"), "--truth", str(tmp_path / "day" / "truth.csv"), "-o", str(tmp_path / "a.json"), "-q")
    assert code == 0, err
    report = json.loads((tmp_path / "a.json").read_text())
    assert (report["truth_total"], report["invoiced_total"], report["missed"], report["false"]) == ("150", "150", [], [])


@pytest.mark.parametrize("outage_at_s, fused_charges", [(TO_CORDON_S - 30, False), (TO_CORDON_S - 4, True)])
def test_a_crossing_in_a_gnss_outage(tmp_path, outage_at_s, fused_charges):
    """A 60 s outage around the crossing (jamming): the receiver's snapshot fixes leave a gap — not charged, and said
    why; the fused positions (odometry through the outage) charge it only where their bound holds: 4 s into the
    outage they do (evidence 44–71 m past the line, bounds 40–44 m), 30 s into it the bound has grown past the HAL."""
    start = dt.datetime(2026, 3, 3, 9, 0, tzinfo=dt.UTC)
    drive = leg(tmp_path / "jam", 0.0, start, 300.0, seed=5, jam_at_s=[round(outage_at_s)], jam_duration_s=60.0, jam_db=40.0, odometry=True, env="rural")
    nmea = charge(drive / "drive.nmea", tmp_path / "nmea.json")
    assert nmea["lines"] == [] and "no position for 6" in nmea["not_charged"][0]["why"]
    fused = charge(drive / "drive-librsf.txt", tmp_path / "fused.json", GOTHENBURG, "--start-time", "2026-03-03T09:00:00Z")
    assert fused["parameters"]["positioning_used"] == "smoothed"
    if fused_charges:
        assert [l["geoobject"] for l in fused["lines"]] == ["G1"]
        assert all(abs(p["distance_m"]) > p["hpl_m"] for p in fused["lines"][0]["evidence"]["after"])
    else:
        assert fused["lines"] == [] and fused["not_charged"][0]["statuses"].get("unavailable", 0) > 0


def test_city_geoobjects_are_checked_shown_and_refused_by_a_section_tariff(tmp_path):
    r = run_cli("geoobjects", "check", str(CITY))
    assert r.returncode == 0, r.stderr
    r = run_cli("geoobjects", "info", str(CITY), "--json")
    info = json.loads(r.stdout)
    assert info["kinds"] == {"gantry": 8, "zone": 1}
    code, err = run_main("process", str(REPO / "samples" / "straight-drive.nmea"), "--geo", str(CITY), "--tariff",
                         str(REPO / "geoobjects" / "example-tariff.toml"), "-o", str(tmp_path / "x.json"))  # fmt: skip
    assert code == 1 and "gantries and zones are charged with a city tariff" in err and "Traceback" not in err
    bad = json.loads(CITY.read_text())
    bad["features"][0]["properties"]["direction"] = "inbound"
    bad["features"][1]["geometry"] = {"type": "Point", "coordinates": [11.98, 57.71]}
    (tmp_path / "bad.geojson").write_text(json.dumps(bad))
    r = run_cli("geoobjects", "check", str(tmp_path / "bad.geojson"))
    assert r.returncode == 1
    said = r.stdout.decode() + r.stderr.decode()
    assert "G1: direction = 'inbound'" in said and "G2: a gantry is a straight LineString" in said


def test_the_example_city_is_what_its_script_builds(tmp_path, monkeypatch):
    import runpy

    module = runpy.run_path(str(REPO / "samples" / "make_city.py"), run_name="not_main")
    monkeypatch.setitem(module["main"].__globals__, "GEO", tmp_path)
    module["main"]()
    for name in ("example-city-roads.geojson", "example-city-gantries.geojson", "example-city-zone.geojson", "example-city.geojson"):
        assert (tmp_path / name).read_bytes() == (REPO / "geoobjects" / name).read_bytes(), name
    built = json.loads((tmp_path / "example-city.geojson").read_text())
    g3 = next(f["properties"] for f in built["features"] if f["properties"]["id"] == "G3")
    assert g3["hal_bound"] == "P3" and g3["hal_m"] == 9.0  # P3 is 30 m from R3: 20 m from the line's end, half of it less 1 m
    code, err = run_main("geoobjects", "build", str(tmp_path / "example-city-roads.geojson"), "--gantries",
                         str(tmp_path / "example-city-gantries.geojson"), "--hal-min", "10", "-o", str(tmp_path / "g.geojson"))  # fmt: skip
    assert code == 0 and "G3: skipped: road P3 crosses the gantry line's extension 20.0 m from its end" in err


OSM = """<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="test">
 <node id="1" lat="57.7000" lon="11.9600" version="1"/>
 <node id="2" lat="57.7020" lon="11.9600" version="1"><tag k="barrier" v="toll_booth"/></node>
 <node id="3" lat="57.7040" lon="11.9600" version="1"/>
 <way id="100" version="1"><nd ref="1"/><nd ref="2"/><nd ref="3"/><tag k="highway" v="primary"/></way>
</osm>
"""


def test_gantries_from_openstreetmap_toll_booths(tmp_path):
    (tmp_path / "t.osm").write_text(OSM)
    code, err = run_main("geoobjects", "build", str(tmp_path / "t.osm"), "--gantries", str(tmp_path / "t.osm"), "-o", str(tmp_path / "g.geojson"))
    assert code == 0, err
    (gantry,) = json.loads((tmp_path / "g.geojson").read_text())["features"]
    assert gantry["properties"]["id"] == "node/2" and gantry["properties"]["road"] == "way/100" and gantry["properties"]["hal_m"] == 50.0
    (east, lat0), (west, lat1) = gantry["geometry"]["coordinates"]
    assert east > 11.96 > west and lat0 == lat1 == 57.702  # across the road, from its right (east, driving north) to its left


def test_a_tariff_naming_a_gantry_the_network_lacks_is_refused(tmp_path):
    text = GOTHENBURG.read_text().replace('start = "07:00"\nend = "08:00"\n', 'start = "07:00"\nend = "08:00"\ngantries = ["G9"]\n', 1)
    assert 'gantries = ["G9"]' in text
    (tmp_path / "t.toml").write_text(text)
    code, err = run_main("process", str(REPO / "samples" / "straight-drive.nmea"), "--geo", str(CITY), "--tariff", str(tmp_path / "t.toml"),
                         "-o", str(tmp_path / "x.json"))  # fmt: skip
    assert code == 1 and "rate 07:00–08:00: G9 is not a gantry of" in err and len(err.strip().splitlines()) == 1


def test_batch_skips_a_city_log_already_done_and_settles_the_day_the_same(weekday, tmp_path):
    logs = sorted(str(p / "drive.nmea") for p in weekday.glob("leg*"))[:3]
    args = ("batch", *logs, "--geo", str(CITY), "--tariff", str(GOTHENBURG), "--vehicle", "ABC123", "-o", str(tmp_path / "out"), "-q", "--json")
    code, err = run_main(*args)
    assert code == 0, err
    first = (tmp_path / "out" / "city-days.json").read_text()
    code, err = run_main(*args)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert code == 0 and summary["skipped"] == 3 and summary["done"] == 0
    assert (tmp_path / "out" / "city-days.json").read_text() == first
