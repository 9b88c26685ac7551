"""Opposite carriageways of one road: HAL not bounded by each other, positions told apart by the direction of travel."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from pyproj import Geod

from conftest import built_geoobjects, run_cli, shared
from tollcli.geoobjects.carriageways import direction_check, heading_deg
from tollcli.charging.invoice import invoice_json
from tollcli.job import pipeline, streaming
from tollcli.job.pipeline import ChargeSettings, charge_log

GEOD = Geod(ellps="WGS84")


def _motorway(tmp_path, name: str, paired: bool = True):
    """5 km of a dual carriageway north of Perpignan: northbound 12.5 m east, southbound 12.5 m west of the axis."""
    lon0, lat0 = 2.9, 42.70
    east, _, _ = GEOD.fwd(lon0, lat0, 90, 12.5)
    west, _, _ = GEOD.fwd(lon0, lat0, 270, 12.5)
    _, lat1, _ = GEOD.fwd(lon0, lat0, 0, 5000)
    same = {"ref": "A7", "name": "A7"} if paired else {}
    features = [
        {"type": "Feature", "properties": {"id": "A7-N", "road_class": "motorway", "direction": "forward", **same},
         "geometry": {"type": "LineString", "coordinates": [[east, lat0], [east, lat1]]}},
        {"type": "Feature", "properties": {"id": "A7-S", "road_class": "motorway", "direction": "forward", **same},
         "geometry": {"type": "LineString", "coordinates": [[west, lat1], [west, lat0]]}},
    ]  # fmt: skip
    roads = tmp_path / f"{name}-roads.geojson"
    roads.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    # (unpaired, each carriageway bounds the other's HAL to 12.5 m: below the design 25 m, built where the operator asks)
    return roads, built_geoobjects(roads, tmp_path / f"{name}.geojson", *(() if paired else ("--hal-min", "5")))


@pytest.fixture(scope="module")
def motorway(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("motorway")
    roads, geo = _motorway(tmp, "paired")
    tariff = tmp / "t.toml"
    tariff.write_text('currency = "EUR"\n[road_class.motorway]\ncar = 2.00\n')
    drives = {}
    for way in ("A7-N", "A7-S"):
        drives[way] = tmp / way
        r = run_cli("simulate", "--route", str(roads), "--via", way, "--geo", str(geo), "--seed", "1", "-o", str(drives[way]), "-q")
        assert r.returncode == 0, r.stderr
    return tmp, geo, tariff, drives


def _invoice(log, geo, tariff, out) -> dict:
    r = run_cli("process", str(log), "--geo", str(geo), "--tariff", str(tariff), "-o", str(out), "-q")
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text())


def test_opposite_carriageways_do_not_bound_each_others_hal(motorway, tmp_path):
    _, geo, _, _ = motorway
    props = {f["properties"]["id"]: f["properties"] for f in json.loads(geo.read_text())["features"]}
    assert props["A7-N"]["opposite"] == ["A7-S"] and props["A7-S"]["opposite"] == ["A7-N"]
    assert props["A7-N"]["hal_m"] == props["A7-S"]["hal_m"] == 50.0  # HAL_max: nothing else is near
    assert run_cli("geoobjects", "check", str(geo)).returncode == 0  # their overlap is allowed: it is told apart by direction
    # the axis runs in the direction of travel: northbound first point south of its last
    axis = np.array(props["A7-N"]["axis"])
    assert axis[0, 1] < axis[-1, 1] and np.array(props["A7-S"]["axis"])[0, 1] > np.array(props["A7-S"]["axis"])[-1, 1]
    # the same two roads without a shared ref or name are two roads 25 m apart: HAL 12.5 m
    _, unpaired = _motorway(tmp_path, "unpaired", paired=False)
    assert [f["properties"]["hal_m"] for f in json.loads(unpaired.read_text())["features"]] == pytest.approx([12.5, 12.5], abs=0.02)


@pytest.mark.parametrize("way, other", [("A7-N", "A7-S"), ("A7-S", "A7-N")])
def test_each_direction_is_charged_its_own_carriageway_only(motorway, way, other):
    tmp, geo, tariff, drives = motorway
    assert json.loads((drives[way] / "truth-geoobjects.json").read_text()) == [way]  # the truth knows the direction too
    doc = _invoice(drives[way] / "drive.nmea", geo, tariff, tmp / f"{way}.json")
    assert [line["geoobject"] for line in doc["lines"]] == [way]
    refused = {line["geoobject"]: line["statuses"] for line in doc["not_charged"]}
    assert refused[other].get("wrong_direction", 0) > 0 and "valid" not in refused[other]
    audit = run_cli("audit", str(tmp / f"{way}.json"), "--truth", str(drives[way] / "truth.csv"), "--geo", str(geo))
    assert audit.returncode == 0 and b"0 missed recognitions, 0 false recognitions" in audit.stderr, audit.stderr


def test_without_pairing_the_same_drive_is_charged_nothing(motorway, tmp_path):
    """Metamorphic contrast: the carriageways as two unrelated roads (HAL 12.5 m) — this receiver's positions cannot
    be protected at that HAL and nothing is charged; paired (HAL 50 m), the drive is charged."""
    _, _, tariff, drives = motorway
    _, unpaired = _motorway(tmp_path, "unpaired", paired=False)
    doc = _invoice(drives["A7-N"] / "drive.nmea", unpaired, tariff, tmp_path / "u.json")
    assert doc["lines"] == []


def test_streamed_invoice_with_carriageways_is_the_whole_log_one(motorway, monkeypatch):
    _, geo, tariff, drives = motorway
    log = str(drives["A7-S"] / "drive.nmea")
    monkeypatch.setattr(pipeline, "STREAM_ROUNDS", False)
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 1_000_000)
    whole = charge_log(log, str(geo), str(tariff), ChargeSettings())[0]
    monkeypatch.setattr(pipeline, "STREAM_ROUNDS", True)
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 23)
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 2048)
    monkeypatch.setattr(streaming, "ROUND_ROWS", 1)
    streamed = charge_log(log, str(geo), str(tariff), ChargeSettings())[0]
    assert invoice_json(streamed) == invoice_json(whole)
    assert any("wrong_direction" in line["statuses"] for line in whole["not_charged"])


def test_heading_and_direction_check():
    line = shapely.LineString([(0, 0), (0, 100), (100, 100)])  # north, then east
    assert heading_deg([line, line], np.array([1.0, 50.0]), np.array([50.0, 101.0])).tolist() == pytest.approx([0.0, 90.0])
    axes = np.array([line] * 5, dtype=object)
    x, y = np.full(5, 1.0), np.full(5, 50.0)
    course = np.array([10.0, 50.0, 180.0, np.nan, 0.0])
    speed = np.array([20.0, 20.0, 20.0, 20.0, 1.0])
    assert direction_check(axes, x, y, course, speed).tolist() == ["", "wrong_direction", "wrong_direction", "direction_unknown",
                                                                   "direction_unknown"]  # fmt: skip


def test_helsinki_carriageways_are_antiparallel_namesakes(tmp_path):
    """From the real map, primary roads tolled: the pairs found are one-way sections of the same street running
    opposite ways; each pair lists the other; the file is clean."""
    geo = tmp_path / "h.geojson"
    r = run_cli("geoobjects", "build", str(shared("osm", "helsinki.osm.pbf")), "--tolled", "highway=primary", "-o", str(geo), "-q",
                "--hal-min", "5")  # (a city's streets: below the design HAL, where the operator asks)
    assert r.returncode == 0, r.stderr
    props = {f["properties"]["id"]: f["properties"] for f in json.loads(geo.read_text())["features"]}
    paired = {gid: p for gid, p in props.items() if "opposite" in p}
    assert len(paired) >= 10
    for gid, p in paired.items():
        assert p["oneway"] and len(p["axis"]) >= 2
        for other in p["opposite"]:
            if other in props:
                assert gid in props[other]["opposite"]
                assert (p.get("ref") and p.get("ref") == props[other].get("ref")) or p["name"] == props[other]["name"]
                a, b = np.array(p["axis"]), np.array(props[other]["axis"])
                assert np.dot(a[-1] - a[0], b[-1] - b[0]) < 0 or len(a) > 2  # overall antiparallel (or curved)
    assert run_cli("geoobjects", "check", str(geo)).returncode == 0


def test_the_revenue_at_risk_does_not_count_the_opposite_carriageway_in_a_city(motorway):
    """An urban drive northbound: the southbound positions the RAIM refuses are still the other carriageway, owed
    nothing — not revenue at risk (before: the direction rule was applied to RAIM-valid positions only)."""
    tmp, geo, tariff, _ = motorway
    drive = tmp / "urban"
    r = run_cli("simulate", "--route", str(tmp / "paired-roads.geojson"), "--via", "A7-N", "--geo", str(geo), "--seed", "1",
                "--env", "urban", "-o", str(drive), "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc = _invoice(drive / "drive.nmea", geo, tariff, tmp / "urban.json")
    refused = {line["geoobject"]: line["statuses"] for line in doc["not_charged"]}
    assert set(refused["A7-S"]) == {"wrong_direction"}
    report = json.loads(run_cli("audit", str(tmp / "urban.json"), "-o", "-", "-q").stdout)
    assert report["money_at_risk"] == "0.00" and [x["geoobject"] for x in report["opposite_carriageway"]] == ["A7-S"]
