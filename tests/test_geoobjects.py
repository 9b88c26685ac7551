"""Geo-object building and checking on hand-built networks."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from conftest import run_cli

from tollcli.geoobjects.design_hal import DesignHal
from tollcli.geoobjects.build import build_geoobjects, check_geoobjects
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
    from pyproj import Geod

    (lon0, lat0), (lon1, lat1) = _line([(1000, 0), (1000, 60)])
    ground_m = Geod(ellps="WGS84").inv(lon0, lat0, lon1, lat1)[2]  # the true distance of the two roads (≈ 59.98 m)
    assert props["hal_m"] == pytest.approx(ground_m / 2, abs=0.002)  # a ground distance, not one of a UTM zone
    assert props["crs_metric"].startswith("+proj=tmerc") and "+lon_0=3 " in props["crs_metric"]
    poly = project([shapely.geometry.shape(doc["features"][0]["geometry"])], props["crs_metric"])[0]
    road = project([shapely.geometry.LineString(_line([(0, 60), (2000, 60)]))], props["crs_metric"])[0]
    # the buffer reaches half-way to the other road and stops: its distance to that road is HAL
    assert shapely.distance(poly, road) == pytest.approx(props["hal_m"], abs=0.05)
    assert poly.area == pytest.approx(2000 * 60 + np.pi * 30**2, rel=0.01)


def test_far_roads_leave_hal_max_and_own_hal_is_respected(tmp_path):
    path = _roads(tmp_path, [
        ({"id": "T1"}, [(0, 0), (1000, 0)]),
        ({"id": "T2", "hal_m": 12}, [(0, 500), (1000, 500)]),
        ({"id": "R", "tolled": False}, [(0, 1000), (1000, 1000)]),
    ])  # fmt: skip
    hal = {f["properties"]["id"]: f["properties"]["hal_m"] for f in build_geoobjects(str(path), DesignHal((40.0, 40.0)))["features"]}
    assert hal == {"T1": 40.0, "T2": 12.0}


def test_connected_roads_do_not_shrink_hal_and_ends_are_trimmed(tmp_path):
    path = _roads(tmp_path, [
        ({"id": "M1"}, [(0, 0), (1000, 0)]),
        ({"id": "M2"}, [(1000, 0), (2000, 0)]),  # the next motorway segment, at a junction
        ({"id": "RAMP", "tolled": False}, [(1000, 0), (1300, -150)]),  # leaves at the junction
    ])  # fmt: skip
    doc = build_geoobjects(str(path), DesignHal((25.0, 25.0)))
    props = {f["properties"]["id"]: f["properties"] for f in doc["features"]}
    assert props["M1"]["hal_m"] == props["M2"]["hal_m"] == 25.0
    # only the junction end is cut: by 2·HAL where the road met leaves at a right angle; along M2, as long as the
    # ramp diverging at 26.6° stays within 2·HAL of it (2·HAL / sin 26.6° = 112 m), so no position on the ramp
    # counts for M2 (the test's metres are 0.1 % off the ground ones)
    assert props["M1"]["length_m"] == pytest.approx(1000 - 2 * 25.0, rel=2e-3)
    assert props["M2"]["length_m"] == pytest.approx(1000 - 2 * 25.0 / np.sin(np.arctan2(150, 300)), rel=2e-3)
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


def test_a_520_km_network_across_three_utm_zones_keeps_ground_distances(tmp_path):
    """A motorway of 520 km along 45° N from 120.3° W across the whole of UTM zone 11 (zones 10, 11, 12) in 10 km
    sections with a free road 60 m (ground) to the north: every section is built in its own frame, its HAL is
    30 m ± 0.02 m, and the buffer's half-width measured on the ellipsoid at the middle of each section is HAL ± 0.02 m —
    where one UTM zone for the file is over 0.4 % off at the far end."""
    from pyproj import Geod

    geod = Geod(ellps="WGS84")
    lat0, lon0 = 45.0, -120.3
    n = 52
    line = geod.fwd_intermediate(lon0, lat0, 90.0, npts=n + 1, del_s=10_000.0, initial_idx=0, terminus_idx=0, return_back_azimuth=True)
    lons, lats = np.array(line.lons), np.array(line.lats)
    # the free road: each vertex 60 m to the north of the motorway's vertex (ground distance, on the ellipsoid)
    az_north = np.array(geod.inv(lons[:-1], lats[:-1], lons[1:], lats[1:], return_back_azimuth=True)[0]) - 90.0
    az_north = np.append(az_north, az_north[-1])
    nlon, nlat, _ = geod.fwd(lons, lats, az_north, np.full(lons.size, 60.0))
    feats = [{"type": "Feature", "properties": {"id": f"M{k:03d}", "road_class": "motorway"},
              "geometry": {"type": "LineString", "coordinates": [[lons[k], lats[k]], [lons[k + 1], lats[k + 1]]]}} for k in range(n)]
    feats.append({"type": "Feature", "properties": {"id": "FREE", "tolled": False},
                  "geometry": {"type": "LineString", "coordinates": np.column_stack([nlon, nlat]).tolist()}})  # fmt: skip
    path = tmp_path / "long.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    assert int((lons[-1] + 180) // 6) + 1 - (int((lons[0] + 180) // 6) + 1) == 2  # three zones
    doc = build_geoobjects(str(path))
    assert len(doc["features"]) == n and len({f["properties"]["crs_metric"] for f in doc["features"]}) >= 6
    widths = []
    for k, f in enumerate(doc["features"]):
        p = f["properties"]
        assert p["hal_m"] == pytest.approx(30.0, abs=0.02), (p["id"], p["hal_m"])
        poly = shapely.geometry.shape(f["geometry"])
        mid_lon, mid_lat, _ = geod.fwd(lons[k], lats[k], geod.inv(lons[k], lats[k], lons[k + 1], lats[k + 1], return_back_azimuth=True)[0], 5_000.0)
        az = geod.inv(lons[k], lats[k], lons[k + 1], lats[k + 1], return_back_azimuth=True)[0] - 90.0
        lo, hi = 25.0, 35.0  # bisection on the ground distance north of the centre line to the polygon's edge
        for _ in range(30):
            mid = (lo + hi) / 2
            x, y, _ = geod.fwd(mid_lon, mid_lat, az, mid)
            lo, hi = (mid, hi) if poly.contains(shapely.Point(x, y)) else (lo, mid)
        widths.append(lo)
    assert np.abs(np.array(widths) - 30.0).max() < 0.02, np.abs(np.array(widths) - 30.0).max()
    geo = tmp_path / "long-geo.geojson"
    geo.write_text(json.dumps(doc))
    assert run_cli("geoobjects", "check", str(geo)).returncode == 0
    # a drive along the whole motorway, across both zone boundaries (120° W, 114° W), under a per-km truck toll: every
    # section charged, each its 10.000 km (ground, junction to junction) at the truck's rate
    everything = [f"M{k:03d}" for k in range(n)]
    assert lons[0] < -120.0 < -114.0 < lons[-1]
    drive = tmp_path / "drive"
    r = run_cli("simulate", "--route", str(path), "--via", ",".join(everything), "--geo", str(geo), "--env", "open",
                "--speed", "100", "--iono", "sbas", "--seed", "2", "-o", str(drive))  # fmt: skip
    assert r.returncode == 0, r.stderr
    tariff = tmp_path / "t.toml"
    tariff.write_text('currency = "EUR"\ntimezone = "America/Los_Angeles"\n[vehicle]\naxles = ["2", "3", "4", "5+"]\n'
                      '[[table]]\nvalid_from = 2026-01-01\n[[table.rate]]\naxles = ["2", "3", "4"]\nper_km = 0.174\n'
                      '[[table.rate]]\naxles = "5+"\nper_km = 0.198\n')  # fmt: skip
    # the papers' ETC (HPL = HAL): the NMEA log does not say its receiver used SBAS, so the solution separation
    # bounds it with single-frequency σ's (HPL 26–30 m against HAL 30 m) and a section can stay unavailable
    r = run_cli("process", str(drive / "drive.nmea"), "--geo", str(geo), "--tariff", str(tariff), "--vehicle-class", "truck",
                "--vehicle-attr", "axles=5+", "--raim", "etc", "-o", str(drive / "inv.json"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    invoice = json.loads((drive / "inv.json").read_text())
    assert [line["geoobject"] for line in invoice["lines"]] == everything
    assert {(line["length_km"], line["rate_per_km"], line["fee"]) for line in invoice["lines"]} == {("10.000", "0.198", "1.98")}
    assert invoice["total"] == "102.96"
