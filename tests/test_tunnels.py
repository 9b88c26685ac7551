"""Tunnels: no GNSS reaches them, so the passage around one is charged once and its outage accuses nobody."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pyproj
import pytest

from conftest import built_geoobjects, run_cli, shared
from tollcli.geoobjects.store import TUNNEL_MIN_SPEED_MPS, tunnel_lengths
from tollcli.charging.recognition import PASSAGE_GAP_S, passage_gaps_s, passages

#: a 6.7 km motorway north of Perpignan; the drive loses every satellite for 216 s from t = 100 s (at 50 km/h:
#: 3 km without GNSS)
ROAD = [[2.9, 42.70], [2.9, 42.73], [2.9, 42.76]]
OUTAGE = ("--jam-at", "100", "--jam-duration", "216", "--jam-db", "60")


def _write_network(tmp_path, name: str, props: dict):
    roads = tmp_path / f"roads-{name}.geojson"
    roads.write_text(json.dumps({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {
        "id": "T1", "name": "Tunnel road", "road_class": "motorway", **props},
        "geometry": {"type": "LineString", "coordinates": ROAD}}]}))  # fmt: skip
    return roads, built_geoobjects(roads, tmp_path / f"geo-{name}.geojson")


@pytest.fixture(scope="module")
def outage_drive(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tunnel")
    roads, geo = _write_network(tmp, "tunnel", {"tunnel_m": 3000})
    drive = tmp / "drive"
    r = run_cli("simulate", "--route", str(roads), "--via", "T1", "--geo", str(geo), "--env", "open", "--speed", "13.89",
                *OUTAGE, "--seed", "1", "-o", str(drive))  # fmt: skip
    assert r.returncode == 0, r.stderr
    tariff = tmp / "t.toml"
    tariff.write_text('currency = "EUR"\n[road_class.motorway]\ncar = 2.00\n')
    return tmp, drive / "drive.nmea", tariff


def _invoice(tmp, log, geo, tariff) -> dict:
    out = tmp / f"invoice-{geo.stem}.json"
    r = run_cli("process", str(log), "--geo", str(geo), "--tariff", str(tariff), "-o", str(out), "-q")
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text())


def test_a_passage_through_a_tunnel_is_charged_once_and_its_outage_accuses_nobody(outage_drive):
    tmp, log, tariff = outage_drive
    doc = _invoice(tmp, log, tmp / "geo-tunnel.geojson", tariff)
    assert [line["fee"] for line in doc["lines"]] == ["2.00"]
    line = doc["lines"][0]
    assert line["entry_utc"] < "2026-03-02T08:01:40" and line["exit_utc"] > "2026-03-02T08:05:16"  # one passage, across it
    kinds = [(f["kind"], f["category"], f["evidence"].get("explains")) for f in doc["findings"]["items"]]
    assert sorted(kinds) == [("tunnel_outage", "expected", k) for k in ("fix_lost_at_speed", "gap", "satellite_collapse")]
    assert all(f["evidence"]["tunnel_geoobjects"] == ["T1"] and f["evidence"]["tunnel_m"] == 3000 for f in doc["findings"]["items"])


def test_the_same_outage_on_an_open_road_is_two_passages_and_suspicious(outage_drive):
    """Metamorphic pair: the same drive and road without the tunnel — the outage now splits the passage (each part is
    charged) and is reported as a possible attack. The tunnel flag is what makes the difference."""
    tmp, log, tariff = outage_drive
    _, geo = _write_network(tmp, "open", {})
    doc = _invoice(tmp, log, geo, tariff)
    assert [line["fee"] for line in doc["lines"]] == ["2.00", "2.00"]
    assert sorted(f["kind"] for f in doc["findings"]["items"]) == ["fix_lost_at_speed", "gap", "satellite_collapse"]


def test_a_short_tunnel_does_not_explain_a_long_outage(outage_drive):
    """A 100 m tunnel takes at most 50 s at the slowest tunnel traffic: a 216 s outage there is not the tunnel's."""
    tmp, log, tariff = outage_drive
    _, geo = _write_network(tmp, "short", {"tunnel_m": 100})
    doc = _invoice(tmp, log, geo, tariff)
    assert len(doc["lines"]) == 2
    assert "tunnel_outage" not in {f["kind"] for f in doc["findings"]["items"]}


def test_passages_allow_a_tunnels_time_without_a_fix():
    geo = SimpleNamespace(ids=np.array(["open", "tunnel"], dtype=object), gap_times_s=lambda: np.array([0.0, 400.0 / TUNNEL_MIN_SPEED_MPS]))
    assert passage_gaps_s(geo).tolist() == [PASSAGE_GAP_S, PASSAGE_GAP_S + 200.0]
    t = np.array([0.0, 1.0, 300.0, 301.0] * 2)
    cols = {"obj": np.repeat([0, 1], 4), "t_s": t, "valid": np.ones(8, bool), "epoch_row": np.arange(8),
            "time_utc": t, "verdict": np.full(8, "valid", object)}  # fmt: skip
    for c in ("raim_status", "test_stat", "threshold", "p_fa", "test_stat_source", "integrity_source"):
        cols[c] = np.zeros(8)
    pos = passages(cols, geo)
    by_object = pos.groupby("geoobject")["passage"].nunique().to_dict()
    assert by_object == {"open": 2, "tunnel": 1}  # 299 s: beyond 120 s, within 120 + 200 s


def test_tunnel_lengths_from_properties():
    props = [{"tunnel_m": 61.9}, {"tunnel": True, "section_length_m": 500.0}, {"tunnel": "no", "length_m": 10.0},
             {"tunnel": "building_passage", "length_m": 30.0}, {}]  # fmt: skip
    assert tunnel_lengths(props).tolist() == [61.9, 500.0, 0.0, 30.0, 0.0]


def test_real_tunnels_in_a_tolled_osm_section_are_measured_and_kept(tmp_path):
    """Alvar Aallon katu (Helsinki) runs through three short tunnels and a building passage: its section records their
    ground length (the tunnel ways' geodesic lengths), and so does the geo-object built from it."""
    from tollcli.geoobjects.osm_network import osm_roads
    from tollcli.geoobjects.osm import read_osm_roads

    path = shared("osm/helsinki.osm.pbf")
    osm = read_osm_roads(str(path))
    roads = osm_roads(osm, ["name=Alvar Aallon katu"])
    sections = [(rid, p) for rid, p in zip(roads.ids, roads.props) if p["tolled"]]
    assert len(sections) == 1 and sections[0][1]["tunnel"]
    ways = osm.ways
    geod = pyproj.Geod(ellps="WGS84")
    expected = 0.0
    for k in np.flatnonzero(((ways["name"] == "Alvar Aallon katu") & ~ways["tunnel"].isin(["", "no"])).to_numpy()):
        a, b = int(osm.offsets[k]), int(osm.offsets[k + 1])
        expected += geod.line_length(osm.lon_deg[a:b], osm.lat_deg[a:b])
    assert expected > 50 and sections[0][1]["tunnel_m"] == pytest.approx(expected, abs=0.1)
    geo = tmp_path / "aalto.geojson"
    r = run_cli("geoobjects", "build", str(path), "--tolled", "name=Alvar Aallon katu", "--hal-min", "2", "-o", str(geo), "-q")
    assert r.returncode == 0, r.stderr
    built = [f["properties"] for f in json.loads(geo.read_text())["features"]]
    assert [p["tunnel_m"] for p in built] == [sections[0][1]["tunnel_m"]] and all(p["tunnel"] for p in built)
