"""Geo-objects built for a design HAL: cut around what comes close, sections junction to junction, any vector format.

A motorway whose ramps run 15 m beside it keeps HAL ≥ 25 m on most of each section (the ramps' stretches cut out);
a drive along it charges each section once, drives on the ramps and the frontage road charge nothing; a GeoJSON
road with a junction in its middle is two sections, each charged its own length; GeoPackage, Shapefile and
FlatGeobuf copies of a network (one in Web Mercator) build the same bytes; real Helsinki, primary tolled.
"""

from __future__ import annotations

import json
import warnings
from decimal import Decimal

import numpy as np
import pytest
import shapely
from conftest import REPO, run_cli, shared

from tollcli.geoobjects.design_hal import DesignHal, parse_design_hal
from tollcli.geoobjects.build import build_from_roads, build_geoobjects
from tollcli.errors import UsageError
from tollcli.spatial import project

LAT0, LON0 = 45.0, 4.8
M_PER_DEG_LAT = 111_132.0
M_PER_DEG_LON = 111_320.0 * np.cos(np.radians(LAT0))


def _lonlat(points_m):
    return [[LON0 + e / M_PER_DEG_LON, LAT0 + n / M_PER_DEG_LAT] for e, n in points_m]


def _write(path, roads):
    feats = [{"type": "Feature", "properties": props, "geometry": {"type": "LineString", "coordinates": _lonlat(pts)}}
             for props, pts in roads]  # fmt: skip
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


SECTION_M = 4000.0
JUNCTIONS_M = [0.0, 4000.0, 8000.0, 12000.0]


def motorway(tmp_path):
    """Three 4 km motorway sections; at each junction an exit ramp leaving from the junction and an entry ramp joining
    at it, each running 15 m beside the carriageway for 300 m, then off to a local road that crosses the motorway on a
    bridge, and a slip road 15 m beside it for 300 m that never meets it (before the design HAL: HAL 7.5 m on every
    section, which single-frequency RAIM cannot protect); another bridge in the middle of the second section, with no junction; a frontage road 60 m away along
    the whole motorway."""
    roads = []
    for k in range(3):
        roads.append(({"id": f"M{k + 1}", "road_class": "motorway", "name": "A7"}, [(JUNCTIONS_M[k], 0), (JUNCTIONS_M[k + 1], 0)]))
    for j, x in enumerate(JUNCTIONS_M):
        roads.append(({"id": f"EXIT{j}", "road_class": "motorway_link", "tolled": False},
                      [(x, 0), (x + 20, -15), (x + 320, -15), (x + 420, -120)]))  # fmt: skip
        roads.append(({"id": f"ENTRY{j}", "road_class": "motorway_link", "tolled": False},
                      [(x - 420, 120), (x - 320, 15), (x - 20, 15), (x, 0)]))  # fmt: skip
        roads.append(({"id": f"SLIP{j}", "road_class": "motorway_link", "tolled": False},  # meets a road, not this one
                      [(x + 40, 15), (x + 340, 15), (x + 440, 120)]))  # fmt: skip
        roads.append(({"id": f"LOCAL{j}", "road_class": "secondary", "tolled": False, "layer": 1},
                      [(x + 150, -600), (x + 150, 600)]))  # fmt: skip
    roads.append(({"id": "BRIDGE", "road_class": "residential", "tolled": False, "bridge": "yes"}, [(6000, -500), (6000, 500)]))
    roads.append(({"id": "FRONTAGE", "road_class": "tertiary", "tolled": False}, [(x, 60) for x in range(-500, 12501, 500)]))
    return _write(tmp_path / "motorway.geojson", roads)


def test_design_hal_options_parse():
    assert parse_design_hal(None) == DesignHal((25.0, 50.0), {})
    design = parse_design_hal(["30", "motorway=40-50", "primary=25"])
    assert design.for_road({"road_class": "motorway"}) == (40.0, 50.0)
    assert design.for_road({"road_class": "primary", "hal_m": 12}) == (12.0, 12.0)  # a road's own hal_m wins
    assert design.for_road({"road_class": "tertiary"}) == (30.0, 30.0)
    for bad in ("x", "50-25", "=30", "-3"):
        with pytest.raises(UsageError):
            parse_design_hal([bad])


def test_a_motorway_with_ramps_beside_it_keeps_its_design_hal(tmp_path):
    doc = build_geoobjects(str(motorway(tmp_path)))
    props = {f["properties"]["id"]: f["properties"] for f in doc["features"]}
    assert sorted(props) == ["M1", "M2", "M3"]
    for p in props.values():
        # the frontage road 60 m away bounds HAL at 30 m; the ramps and the bridges are cut around, not bounding
        assert p["hal_m"] == pytest.approx(30.0, rel=0.01) and p["hal_bound"] == "road" and p["nearest_road"] == "FRONTAGE"
        assert p["length_m"] >= 0.70 * p["section_length_m"] and p["section_length_m"] == pytest.approx(SECTION_M, rel=2e-3)
    assert "BRIDGE" in props["M2"]["crossings"] and len(props["M2"]["parts"]) == 2  # cut around the bridge: two parts
    # the rule before the design HAL (cut around only what comes within 2 · 5 m): the slip roads hold HAL at 7.5 m
    before = build_geoobjects(str(tmp_path / "motorway.geojson"), parse_design_hal(["5-50"]))
    assert [f["properties"]["hal_m"] for f in before["features"]] == pytest.approx([7.45] * 3, abs=0.05)
    assert "parts" not in props["M1"] and "parts" not in props["M3"]
    # no point of a road it does not meet lies inside any geo-object (exactly: within HAL of the polygon's edge)
    roads = json.loads((tmp_path / "motorway.geojson").read_text())["features"]
    for f in doc["features"]:
        p = f["properties"]
        poly = project([shapely.geometry.shape(f["geometry"])], p["crs_metric"])[0]
        for r in roads:
            if r["properties"]["id"].startswith(("LOCAL", "FRONTAGE", "BRIDGE")):
                line = project([shapely.geometry.shape(r["geometry"])], p["crs_metric"])[0]
                assert shapely.distance(poly, line) >= p["hal_m"] - 0.01, (p["id"], r["properties"]["id"])


def _charged(tmp_path, roads, geo, via, name, *extra):
    drive = tmp_path / name
    r = run_cli("simulate", "--route", str(roads), "--via", via, "--geo", str(geo), "--env", "open", "--speed", "90",
                "--iono", "sbas", "--seed", "5", "-o", str(drive))  # fmt: skip
    assert r.returncode == 0, r.stderr
    inv = drive / "inv.json"
    r = run_cli("process", str(drive / "drive.nmea"), "--geo", str(geo), "--tariff", str(REPO / "geoobjects" / "example-tariff.toml"),
                "-q", "-o", str(inv), *extra)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return json.loads(inv.read_text())


def test_drives_on_the_carriageway_charge_each_section_once_ramps_and_frontage_nothing(tmp_path):
    roads = motorway(tmp_path)
    geo = tmp_path / "geo.geojson"
    assert run_cli("geoobjects", "build", str(roads), "-o", str(geo), "-q").returncode == 0
    invoice = _charged(tmp_path, roads, geo, "M1,M2,M3", "carriageway", "--raim", "etc")
    assert [line["geoobject"] for line in invoice["lines"]] == ["M1", "M2", "M3"]  # once each, M2 across its two parts
    m2 = invoice["lines"][1]
    assert m2["parts_seen"] == [1, 2] and "parts_seen" not in invoice["lines"][0]
    for via in ("FRONTAGE", "EXIT1", "ENTRY2", "SLIP1"):
        for raim in ("etc", "ss"):
            assert _charged(tmp_path, roads, geo, via, f"{via}-{raim}", "--raim", raim)["lines"] == [], (via, raim)


def test_a_junction_in_the_middle_of_a_geojson_road_makes_two_sections(tmp_path):
    """A 1 577 m road with a side road meeting its middle vertex: two sections, and a drive over the first half is
    charged that half at its own length under a per-km tariff."""
    roads = _write(tmp_path / "roads.geojson", [
        ({"id": "N7", "road_class": "trunk"}, [(0, 0), (788.5, 0), (1577, 0)]),
        ({"id": "SIDE", "tolled": False}, [(788.5, 0), (788.5, 900)]),
    ])  # fmt: skip
    doc = build_geoobjects(str(roads))
    props = {f["properties"]["id"]: f["properties"] for f in doc["features"]}
    assert sorted(props) == ["N7/1", "N7/2"]
    assert props["N7/1"]["section_length_m"] == pytest.approx(788.5, rel=2e-3)
    geo = tmp_path / "geo.geojson"
    geo.write_text(json.dumps(doc))
    half = _write(tmp_path / "half.geojson", [({"id": "FIRST"}, [(0, 0), (700, 0)])])
    tariff = tmp_path / "km.toml"
    tariff.write_text('currency = "EUR"\ntimezone = "Europe/Paris"\n[[table]]\nvalid_from = 2020-01-01\n'
                      '[[table.rate]]\ngeoobject = "N7"\nper_km = 0.20\n')  # fmt: skip
    drive = tmp_path / "d"
    r = run_cli("simulate", "--route", str(half), "--geo", str(geo), "--env", "open", "--speed", "20", "--iono", "sbas",
                "--seed", "1", "-o", str(drive))  # fmt: skip
    assert r.returncode == 0, r.stderr
    inv = drive / "inv.json"
    r = run_cli("process", str(drive / "drive.nmea"), "--geo", str(geo), "--tariff", str(tariff), "--raim", "etc", "-q", "-o", str(inv))
    assert r.returncode == 0, r.stderr
    lines = json.loads(inv.read_text())["lines"]
    assert [line["geoobject"] for line in lines] == ["N7/1"]  # the road's rate applies to its sections
    km = Decimal(lines[0]["length_km"])
    assert abs(km - Decimal("0.7885")) <= Decimal("0.002") and Decimal(lines[0]["fee"]) == (km * Decimal("0.20")).quantize(Decimal("0.01"))


def test_a_road_crossing_on_another_level_does_not_cut_it_into_sections(tmp_path):
    roads = _write(tmp_path / "roads.geojson", [
        ({"id": "A"}, [(0, 0), (1000, 0), (2000, 0)]),
        ({"id": "BRIDGE", "tolled": False, "bridge": "yes"}, [(1000, -500), (1000, 0), (1000, 500)]),
    ])  # fmt: skip
    doc = build_geoobjects(str(roads))
    (only,) = doc["features"]
    assert only["properties"]["id"] == "A" and only["properties"]["crossings"] == ["BRIDGE"]
    assert len(only["properties"]["parts"]) == 2 and only["properties"]["gap_m"] > 0


def test_a_passage_spans_the_stretch_between_parts(tmp_path):
    """The stretch cut out between two parts is driven without a fix inside: a slow vehicle crossing it (2 m/s) is
    still one passage, charged once."""
    from tollcli.geoobjects.store import TUNNEL_MIN_SPEED_MPS, load_geoobjects
    from tollcli.charging.recognition import PASSAGE_GAP_S, passage_gaps_s

    roads = _write(tmp_path / "roads.geojson", [
        ({"id": "A"}, [(0, 0), (2000, 0), (4000, 0)]),
        ({"id": "UNDER", "tolled": False, "tunnel": "yes"}, [(1500, -800), (2000, 0), (2500, 800)]),
    ])  # fmt: skip
    geo = tmp_path / "g.geojson"
    geo.write_text(json.dumps(build_geoobjects(str(roads))))
    loaded = load_geoobjects(str(geo))
    gap = json.loads(geo.read_text())["features"][0]["properties"]["gap_m"]
    assert gap > 200 and loaded.gap_m.tolist() == [gap]
    assert passage_gaps_s(loaded).tolist() == pytest.approx([PASSAGE_GAP_S + gap / TUNNEL_MIN_SPEED_MPS])


@pytest.mark.parametrize("driver, suffix, crs", [("GPKG", ".gpkg", "EPSG:4326"), ("ESRI Shapefile", ".shp", "EPSG:4326"),
                                                 ("GPKG", ".gpkg", "EPSG:3857"), ("FlatGeobuf", ".fgb", "EPSG:3857")],
                         ids=["gpkg", "shp", "gpkg-3857", "fgb-3857"])  # fmt: skip
def test_other_vector_formats_build_the_same_bytes(tmp_path, driver, suffix, crs):
    import geopandas

    source = REPO / "geoobjects" / "example-roads.geojson"
    frame = geopandas.read_file(source).to_crs(crs)
    copy = tmp_path / f"roads{suffix}"
    frame.to_file(copy, driver=driver)
    outs = []
    for roads in (source, copy):
        out = tmp_path / f"{roads.name}.geojson"
        r = run_cli("geoobjects", "build", str(roads), "-o", str(out), "-q")
        assert r.returncode == 0, r.stderr
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def test_a_vector_file_without_a_crs_is_refused(tmp_path):
    import geopandas

    frame = geopandas.read_file(REPO / "geoobjects" / "example-roads.geojson")
    frame = frame.set_crs(None, allow_override=True)
    path = tmp_path / "nocrs.shp"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # pyogrio warns that a file without a CRS may be unusable: it is
        frame.to_file(path)
    r = run_cli("geoobjects", "build", str(path), "-o", str(tmp_path / "g.geojson"))
    err = r.stderr.decode()
    assert r.returncode == 1 and "declares no coordinate reference system" in err and "Traceback" not in err


def test_build_refuses_what_check_would_refuse_with_the_same_words(tmp_path):
    roads = _write(tmp_path / "roads.geojson", [({"id": "TINY", "hal_m": 0.79}, [(0, 0), (500, 0)])])
    r = run_cli("geoobjects", "build", str(roads), "-o", str(tmp_path / "g.geojson"))
    err = r.stderr.decode()
    assert r.returncode == 1 and "TINY: hal_m 0.79 m below the minimum 5 m" in err and not (tmp_path / "g.geojson").exists()


def test_sections_with_no_stretch_at_the_design_hal_fall_back_and_are_listed(tmp_path):
    roads = _write(tmp_path / "roads.geojson", [
        ({"id": "NARROW"}, [(0, 0), (1000, 0)]),
        ({"id": "STREET", "tolled": False}, [(-100, 30), (1100, 30)]),  # a parallel street 30 m away all along
    ])  # fmt: skip
    geo = tmp_path / "g.geojson"
    # by default no fallback: the section is skipped, naming the road that takes it (a newcomer's build kept 1 m
    # geo-objects at HAL 5 m that charged a whole section from one position)
    r = run_cli("geoobjects", "build", str(roads), "-o", str(geo), "--json")
    assert r.returncode == 1 and "NARROW: no stretch of 13.9 m can have HAL 25 m" in r.stderr.decode() and "(STREET)" in r.stderr.decode()
    r = run_cli("geoobjects", "build", str(roads), "-o", str(geo), "--json", "--hal-min", "5")  # the operator asks
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["below_design_hal"] == [{"id": "NARROW", "hal_m": 15.0, "design_hal_m": [25.0, 50.0]}]
    assert "NARROW: HAL 15 m, below its design 25 m" in r.stderr.decode()
    info = json.loads(run_cli("geoobjects", "info", str(geo), "--json").stdout)
    assert info["below_design_hal"] == ["NARROW"] and info["covered_share_at_min_hal"] == 0.0
    assert info["features"][0]["nearest_road"] == "STREET" and info["features"][0]["nearest_road_m"] == pytest.approx(30.0, abs=0.1)


def test_helsinki_primary_at_design_hal_25(tmp_path):
    """Real central Helsinki with its primary roads tolled, design HAL 25 m: every geo-object passes check, no point
    of a road a section does not meet lies inside its geo-object (opposite carriageways aside: they are told apart
    by the direction of travel), and geo-objects of HAL ≥ 25 m cover a share of the primary length (none before)."""
    from tollcli.geoobjects.osm_network import osm_roads
    from tollcli.geoobjects.osm import read_osm_roads

    path = shared("osm", "helsinki.osm.pbf")
    geo = tmp_path / "h.geojson"
    r = run_cli("geoobjects", "build", str(path), "--tolled", "highway=primary", "--hal", "25", "-o", str(geo), "-q")
    assert r.returncode == 0, r.stderr
    assert run_cli("geoobjects", "check", str(geo)).returncode == 0
    info = json.loads(run_cli("geoobjects", "info", str(geo), "--json").stdout)
    assert info["covered_share_at_min_hal"] >= 0.15 and info["tolled_length_m"] == pytest.approx(3550, rel=0.01)
    roads = osm_roads(read_osm_roads(str(path)), ["highway=primary"])
    index = {rid: k for k, rid in enumerate(roads.ids)}
    doc = json.loads(geo.read_text())
    lines = np.asarray(roads.lines, dtype=object)
    for f in doc["features"]:
        p = f["properties"]
        k = index[p["id"]]
        poly = project([shapely.geometry.shape(f["geometry"])], p["crs_metric"])[0]
        metric = project(lines, p["crs_metric"])
        near = np.flatnonzero(shapely.dwithin(metric, poly, 1.0))
        for j in near.tolist():
            met = (min(j, k), max(j, k)) in roads.junctions or j == k
            if met or roads.ids[j] in p.get("opposite", []):
                continue
            assert not shapely.intersects(poly, metric[j]), (p["id"], roads.ids[j])
            assert shapely.distance(poly, metric[j]) > 0.0


def test_build_from_roads_keeps_the_design_of_each_class(tmp_path):
    from tollcli.geoobjects.build import roads_of

    roads = _write(tmp_path / "roads.geojson", [
        ({"id": "FAST", "road_class": "motorway"}, [(0, 0), (1000, 0)]),
        ({"id": "SLOW", "road_class": "primary"}, [(0, 1000), (1000, 1000)]),
    ])  # fmt: skip
    doc, skipped = build_from_roads(roads_of(str(roads)), str(roads), parse_design_hal(["motorway=45", "primary=25-30"]))
    hal = {f["properties"]["id"]: f["properties"]["hal_m"] for f in doc["features"]}
    assert hal == {"FAST": 45.0, "SLOW": 30.0} and skipped == []


def test_info_tells_what_a_geoobject_file_holds():
    r = run_cli("geoobjects", "info", str(REPO / "geoobjects" / "example-geoobjects.geojson"))
    out = r.stdout.decode()
    assert r.returncode == 0 and "2 geo-objects" in out and "HAL 40–50 m: 2" in out
    assert "by HAL ≥ 25 m: 3.040 km (94.9 %)" in out
    assert any(line.startswith("A9-N1\t40.023\t25-50\t") and line.endswith("\troad\tD900\t80.05") for line in out.splitlines())
