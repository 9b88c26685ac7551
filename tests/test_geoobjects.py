"""Geo-object building and checking on hand-built networks."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from conftest import run_cli

from tollcli.charging.geoobjects import build_geoobjects, check_geoobjects
from tollcli.errors import DataError
from tollcli.spatial import metric_crs, project

LAT0, LON0 = 42.70, 2.90
M_PER_DEG_LAT = 111_132.0
M_PER_DEG_LON = 111_320.0 * np.cos(np.radians(LAT0))


def _line(points_m):
    """Local east/north metres around (LAT0, LON0) → lon/lat coordinates."""
    return [[LON0 + e / M_PER_DEG_LON, LAT0 + n / M_PER_DEG_LAT] for e, n in points_m]


def _roads(tmp_path, roads, name="roads.geojson"):
    feats = [{"type": "Feature", "properties": props, "geometry": {"type": "LineString", "coordinates": _line(pts)}}
             for props, pts in roads]  # fmt: skip
    path = tmp_path / name
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def _metric(doc):
    polys = [shapely.geometry.shape(f["geometry"]) for f in doc["features"]]
    return project(polys, metric_crs(polys))


def test_parallel_non_tolled_road_60_m_away_gives_hal_30(tmp_path):
    path = _roads(tmp_path, [
        ({"id": "A9-1", "road_class": "motorway"}, [(0, 0), (2000, 0)]),
        ({"id": "D1", "tolled": False}, [(0, 60), (2000, 60)]),
    ])  # fmt: skip
    doc = build_geoobjects(str(path))
    assert [f["properties"]["id"] for f in doc["features"]] == ["A9-1"]  # non-tolled roads give no geo-object
    props = doc["features"][0]["properties"]
    assert props["hal_m"] == pytest.approx(30.0, abs=0.05) and props["crs_metric"] == "EPSG:32631"
    poly = _metric(doc)[0]
    road = project([shapely.geometry.LineString(_line([(0, 60), (2000, 60)]))], "EPSG:32631")[0]
    # the buffer reaches half-way to the other road and stops: its distance to that road is HAL
    assert shapely.distance(poly, road) == pytest.approx(props["hal_m"], abs=0.05)
    assert poly.area == pytest.approx(2000 * 60 + np.pi * 30**2, rel=0.01)


def test_far_roads_leave_hal_max_and_own_hal_is_respected(tmp_path):
    path = _roads(tmp_path, [
        ({"id": "T1"}, [(0, 0), (1000, 0)]),
        ({"id": "T2", "hal_m": 12}, [(0, 500), (1000, 500)]),
        ({"id": "R", "tolled": False}, [(0, 1000), (1000, 1000)]),
    ])  # fmt: skip
    hal = {f["properties"]["id"]: f["properties"]["hal_m"] for f in build_geoobjects(str(path), hal_max_m=40)["features"]}
    assert hal == {"T1": 40.0, "T2": 12.0}


def test_connected_roads_do_not_shrink_hal_and_ends_are_trimmed(tmp_path):
    path = _roads(tmp_path, [
        ({"id": "M1"}, [(0, 0), (1000, 0)]),
        ({"id": "M2"}, [(1000, 0), (2000, 0)]),  # the next motorway segment, at a junction
        ({"id": "RAMP", "tolled": False}, [(1000, 0), (1300, -150)]),  # leaves at the junction
    ])  # fmt: skip
    doc = build_geoobjects(str(path), hal_max_m=25.0)
    props = {f["properties"]["id"]: f["properties"] for f in doc["features"]}
    assert props["M1"]["hal_m"] == props["M2"]["hal_m"] == 25.0
    # only the junction end is cut, by 2·HAL (lengths in UTM metres: within 0.2 % of the local ones)
    assert props["M1"]["length_m"] == pytest.approx(1000 - 2 * 25.0, rel=2e-3)
    assert props["M2"]["length_m"] == pytest.approx(1000 - 2 * 25.0, rel=2e-3)
    assert check_geoobjects_ok(tmp_path, doc)


def check_geoobjects_ok(tmp_path, doc) -> bool:
    out = tmp_path / "go.geojson"
    out.write_text(json.dumps(doc))
    return check_geoobjects(str(out)) == []


def _polygons(tmp_path, feats):
    path = tmp_path / "bad.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return str(path)


def _square(e0, n0, size=50.0):
    pts = _line([(e0, n0), (e0 + size, n0), (e0 + size, n0 + size), (e0, n0 + size), (e0, n0)])
    return {"type": "Polygon", "coordinates": [pts]}


def test_check_reports_each_problem_with_its_feature(tmp_path):
    bow_tie = {"type": "Polygon", "coordinates": [_line([(0, 1000), (50, 1050), (50, 1000), (0, 1050), (0, 1000)])]}
    feats = [
        {"type": "Feature", "properties": {"id": "ok", "hal_m": 20}, "geometry": _square(0, 0)},
        {"type": "Feature", "properties": {"id": "ok", "hal_m": 20}, "geometry": _square(500, 0)},  # duplicate id
        {"type": "Feature", "properties": {"hal_m": 20}, "geometry": _square(1000, 0)},  # missing id
        {"type": "Feature", "properties": {"id": "over", "hal_m": 20}, "geometry": _square(25, 25)},  # overlaps "ok"
        {"type": "Feature", "properties": {"id": "small", "hal_m": 2}, "geometry": _square(2000, 0)},
        {"type": "Feature", "properties": {"id": "bow", "hal_m": 20}, "geometry": bow_tie},  # self-intersecting
        {"type": "Feature", "properties": {"id": "utm", "hal_m": 20},
         "geometry": {"type": "Polygon", "coordinates": [[[500000, 4700000], [500050, 4700000], [500050, 4700050], [500000, 4700000]]]}},
        {"type": "Feature", "properties": {"id": "line", "hal_m": 20}, "geometry": {"type": "LineString", "coordinates": _line([(0, 0), (1, 1)])}},
    ]  # fmt: skip
    found = {(f.feature, f.problem.split(" ")[0]) for f in check_geoobjects(_polygons(tmp_path, feats))}
    assert ("ok", "duplicate") in found and ("#2", "missing") in found and ("small", "hal_m") in found
    assert ("bow", "invalid") in found and ("utm", "coordinates") in found and ("line", "geometry") in found
    assert any(fid == "ok" and what == "overlaps" for fid, what in found)


def test_bad_files_are_data_errors(tmp_path):
    (tmp_path / "x.geojson").write_text("{not json")
    with pytest.raises(DataError, match="not a GeoJSON"):
        build_geoobjects(str(tmp_path / "x.geojson"))
    path = _roads(tmp_path, [({"id": "A"}, [(0, 0), (100, 0)]), ({"id": "A"}, [(0, 500), (100, 500)])])
    with pytest.raises(DataError, match="duplicate road ids A"):
        build_geoobjects(str(path))
    path = _roads(tmp_path, [({"id": "B", "tolled": False}, [(0, 0), (100, 0)])], "free.geojson")
    with pytest.raises(DataError, match="no tolled road"):
        build_geoobjects(str(path))


def test_cli_build_then_check(tmp_path):
    roads = _roads(tmp_path, [({"id": "A9-1"}, [(0, 0), (2000, 0)]), ({"id": "D1", "tolled": False}, [(0, 60), (2000, 60)])])
    out = tmp_path / "go.geojson"
    proc = run_cli("geoobjects", "build", str(roads), "-o", str(out))
    assert proc.returncode == 0 and "HAL 29.9" in proc.stderr.decode()
    assert run_cli("geoobjects", "check", str(out)).returncode == 0
    proc = run_cli("geoobjects", "check", str(out), "--hal-min", "35", "--json")
    assert proc.returncode == 1 and json.loads(proc.stdout.decode().splitlines()[0])[0]["feature"] == "A9-1"
    bad = run_cli("geoobjects", "build", str(tmp_path / "missing.geojson"))
    assert bad.returncode == 2 and b"Traceback" not in bad.stderr


# ---------------------------------------------------------------- process refuses what check rejects
def _example() -> dict:
    from conftest import REPO

    return json.loads((REPO / "geoobjects" / "example-geoobjects.geojson").read_text())


def _process_with(tmp_path, geo: dict):
    from conftest import REPO

    path = tmp_path / "geo.geojson"
    path.write_text(json.dumps(geo))
    return run_cli("process", str(REPO / "samples" / "sim" / "rural-clean" / "drive.nmea"), "--geo", str(path),
                   "--tariff", str(REPO / "geoobjects" / "example-tariff.toml"), "-q", "-o", str(tmp_path / "inv.json"))  # fmt: skip


def _twin(geo: dict) -> dict:
    twin = json.loads(json.dumps(geo["features"][0]))
    twin["properties"]["id"] = "A9-N1-copy"
    return {**geo, "features": [*geo["features"], twin]}


def _to_web_mercator(geo: dict) -> dict:
    from pyproj import Transformer

    to = Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True)
    out = json.loads(json.dumps(geo))
    for f in out["features"]:
        f["geometry"]["coordinates"] = [[list(to.transform(x, y)) for x, y in ring] for ring in f["geometry"]["coordinates"]]
    return out


def _shifted_lon(geo: dict) -> dict:
    out = json.loads(json.dumps(geo))
    out["features"][1]["geometry"]["coordinates"] = [[[x + 197.0, y] for x, y in ring]
                                                     for ring in out["features"][1]["geometry"]["coordinates"]]  # fmt: skip
    return out


@pytest.mark.parametrize("damage, says", [(_twin, "overlaps"), (_to_web_mercator, "longitude/latitude"),
                                          (_shifted_lon, "longitude/latitude")], ids=["duplicate", "epsg3857", "lon200"])  # fmt: skip
def test_process_refuses_a_network_check_rejects(tmp_path, damage, says):
    result = _process_with(tmp_path, damage(_example()))
    err = result.stderr.decode()
    assert result.returncode == 1 and says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "inv.json").exists()
    assert run_cli("geoobjects", "check", str(tmp_path / "geo.geojson")).returncode == 1


def test_reordered_features_give_the_same_charges(tmp_path):
    geo = _example()
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir(), second.mkdir()
    assert _process_with(first, geo).returncode == 0
    assert _process_with(second, {**geo, "features": geo["features"][::-1]}).returncode == 0
    a, b = (json.loads((d / "inv.json").read_text()) for d in (first, second))
    assert a["lines"] and a["lines"] == b["lines"] and a["total"] == b["total"] and a["not_charged"] == b["not_charged"]
