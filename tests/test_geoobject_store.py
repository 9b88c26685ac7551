"""The compiled geo-object store: made by build and compile as process would make it, mapped, and touched only near
the track. None of it may change a geo-object file or an invoice by a byte."""

from __future__ import annotations

import hashlib
import json
import math
import sys

import numpy as np
import pytest
import shapely
from conftest import REPO, SAMPLES, run_cli

from tollcli.geoobjects import store as geoobject_store
from tollcli.geoobjects.store_files import manifest_of, manifest_sha256, read_verified
from tollcli.geoobjects.build import build_from_roads, roads_of
from tollcli.charging.recognition import candidate_pairs
from tollcli.errors import DataError
from tollcli.spatial import feature_collection_text

sys.path.insert(0, str(REPO / "benchmarks"))
from process_throughput import roads as parallel_roads  # noqa: E402

ROADS = str(REPO / "geoobjects" / "example-roads.geojson")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _dumps(doc: dict) -> str:
    return json.dumps(doc, separators=(",", ":"), sort_keys=True) + "\n"


@pytest.mark.parametrize("chunk", [1, 3, 2000])
def test_the_streamed_text_is_json_dumps(chunk):
    """What build writes a few features at a time is json.dumps of the whole document, whether the geometries are
    GeoJSON dicts or shapely polygons not yet converted."""
    as_dicts, _ = build_from_roads(roads_of(ROADS), ROADS)
    as_shapes, _ = build_from_roads(roads_of(ROADS), ROADS, shapely_geometry=True)
    assert isinstance(as_shapes["features"][0]["geometry"], shapely.Geometry)
    expected = _dumps(as_dicts)
    assert "".join(feature_collection_text(as_dicts, chunk)) == expected
    assert "".join(feature_collection_text(as_shapes, chunk)) == expected
    multi = {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"id": "m"},
             "geometry": shapely.MultiPolygon([shapely.box(0, 0, 0.1, 0.1), shapely.box(1, 1, 1.1, 1.1).difference(shapely.box(1.02, 1.02, 1.05, 1.05))])}]}  # fmt: skip
    mapped = {**multi, "features": [{**multi["features"][0], "geometry": shapely.geometry.mapping(multi["features"][0]["geometry"])}]}
    assert "".join(feature_collection_text(multi, chunk)) == _dumps(mapped)


def _same_columns(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for name in a:
        assert (a[name] == b[name]) if name == "strings" else np.array_equal(a[name], b[name]), name


def test_build_leaves_the_store_process_would_make(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    geo = tmp_path / "geo.geojson"
    r = run_cli("geoobjects", "build", ROADS, "-o", str(geo), "-q")
    assert r.returncode == 0, r.stderr
    digest = hashlib.sha256(geo.read_bytes()).hexdigest()
    store = geoobject_store.store_path(digest)
    assert store.is_dir() and not list(store.parent.glob("*.tmp"))
    compiled, parsed_digest = geoobject_store.compile_file(str(geo))
    assert parsed_digest == digest
    mapped, store_digest = read_verified(store, geoobject_store.STORE_FORMAT, digest)
    _same_columns(mapped, compiled)
    assert store_digest == manifest_sha256(manifest_of(compiled, geoobject_store.STORE_FORMAT, digest))  # as in memory


def test_compile_command(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    r = run_cli("geoobjects", "compile", GEO, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["sha256"] == hashlib.sha256(open(GEO, "rb").read()).hexdigest()
    assert summary["geoobjects"] == 2 and summary["store"].endswith(f"{summary['sha256']}.v{geoobject_store.STORE_FORMAT}")
    first = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "cache" / "geoobjects").rglob("*.npy")}
    assert run_cli("geoobjects", "compile", GEO, "-q").returncode == 0  # there already: mapped, not made again
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "cache" / "geoobjects").rglob("*.npy")} == first
    bad = tmp_path / "bad.geojson"
    doc = json.loads(open(GEO).read())
    doc["features"][1]["properties"]["id"] = doc["features"][0]["properties"]["id"]
    bad.write_text(json.dumps(doc))
    r = run_cli("geoobjects", "compile", str(bad))
    assert r.returncode == 1 and b"duplicate id" in r.stderr and b"Traceback" not in r.stderr
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    r = run_cli("geoobjects", "compile", GEO)
    assert r.returncode == 2 and b"no cache" in r.stderr


def test_a_digest_the_file_no_longer_has_is_refused(tmp_path, monkeypatch):
    """A batch hashes the geo-object file once; a file changed since is not compiled under the old digest."""
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path))
    with pytest.raises(DataError, match="changed while it was read"):
        geoobject_store.load_geoobjects(GEO, sha256="0" * 64)
    assert not list(tmp_path.rglob("*.npy"))
    right = hashlib.sha256(open(GEO, "rb").read()).hexdigest()
    assert geoobject_store.load_geoobjects(GEO, sha256=right).source_sha256 == right


def test_recognition_decodes_only_the_geoobjects_near_the_track(tmp_path, monkeypatch):
    """On a network of 3 000 sections (parallel roads 300 m apart), a 2 km drive decodes the polygons of the few
    sections whose boxes hold a position — the run's cost follows the drive, not the network."""
    import pandas as pd

    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    roads = tmp_path / "roads.geojson"
    roads.write_text(json.dumps(parallel_roads(3000, 100_000.0)))
    geo_file = tmp_path / "geo.geojson"
    assert run_cli("geoobjects", "build", str(roads), "-o", str(geo_file), "-q").returncode == 0
    geo = geoobject_store.load_geoobjects(str(geo_file))
    assert geo.store is not None and len(geo.ids) > 2900
    from process_throughput import point

    s = np.arange(0.0, 2000.0, 25.0)
    lonlat = np.array([point(v, 0.0) for v in s])
    epochs = pd.DataFrame({"lon_deg": lonlat[:, 0], "lat_deg": lonlat[:, 1]})
    rows, obj, _, _ = candidate_pairs(epochs, geo)
    decoded = np.flatnonzero(~shapely.is_missing(geo.polygons._decoded))
    assert set(np.unique(obj)) == {i for i in range(len(geo.ids)) if geo.ids[i] in {f"R0-{k}" for k in range(8)}}
    assert len(decoded) <= 2 * math.ceil(2000 / 250) + 4  # the sections along the track and their boxes' neighbours
    assert rows.size > len(s) // 2  # (each 250 m section keeps its middle: its ends are trimmed at the junctions)


def test_invoices_from_the_store_and_without_it_are_the_same(tmp_path, monkeypatch):
    out = []
    for cache in (str(tmp_path / "cache"), str(tmp_path / "cache"), "off"):
        monkeypatch.setenv("TOLLCLI_CACHE_DIR", cache)
        target = tmp_path / f"{len(out)}.json"
        r = run_cli("process", str(SAMPLES / "sim" / "urban-fault" / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "-o", str(target), "-q")
        assert r.returncode == 0, r.stderr
        out.append(target.read_bytes())
    assert out[0] == out[1] == out[2]


def _features_as_loaded(path) -> list:
    """The features as json.load and shapely.shape give them (geometries as shapely, properties as they are)."""
    from tollcli.spatial import feature_geometry, read_features

    return [{"type": f.get("type"), "properties": f.get("properties"), "geometry": feature_geometry(f)[0]} for f in read_features(path)]


@pytest.mark.parametrize("indent", [None, 3])
def test_streamed_features_are_json_loads_ones(tmp_path, monkeypatch, indent):
    """Read 7 bytes at a time, made into geometries 2 features at a time, in any member order, pretty or not: the same
    properties and the same coordinates, bit for bit, as json.load; the digest is the file's."""
    from tollcli.geoobjects import geojson_stream

    monkeypatch.setattr(geojson_stream, "READ_BYTES", 7)
    monkeypatch.setattr(geojson_stream, "BLOCK", 2)
    doc = json.loads(open(GEO, encoding="utf-8").read())
    multi = shapely.MultiPolygon([shapely.box(2.0, 42.0, 2.001, 42.001), shapely.box(2.01, 42.0, 2.011, 42.001)])
    doc["features"].append({"type": "Feature", "properties": {"id": "multi é", "hal_m": 25.0, "note": [1, {"a": None}]},
                            "geometry": shapely.geometry.mapping(multi)})  # fmt: skip
    doc = {"features": doc["features"], "tollcli": {"skipped": [1.5e-300, -0.0]}, "type": "FeatureCollection"}
    path = tmp_path / "g.geojson"
    path.write_text(json.dumps(doc, indent=indent, ensure_ascii=False), encoding="utf-8")
    features, digest = geojson_stream.stream_features(str(path))
    assert digest == hashlib.sha256(path.read_bytes()).hexdigest()
    expected = _features_as_loaded(str(path))
    assert [f["properties"] for f in features] == [f["properties"] for f in expected]
    assert (shapely.to_wkb([f["geometry"] for f in features]) == shapely.to_wkb([f["geometry"] for f in expected])).all()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"type": "FeatureCollection", "features": [{"type": "Feature", ', "not a GeoJSON file"),
        ('{"type": "FeatureCollection", "features": []} x', "extra data"),
        ('[1, 2]', "not a GeoJSON FeatureCollection"),
        ('{"type": "Topology", "features": []}', "not a GeoJSON FeatureCollection"),
        ('{"type": "FeatureCollection", "features": 5}', "not a GeoJSON FeatureCollection"),
        ('{"type": "FeatureCollection", "crs": {"properties": {"name": "EPSG:3857"}}, "features": []}', "WGS-84"),
    ],
)
def test_streamed_reading_says_what_is_wrong(tmp_path, text, message):
    from tollcli.geoobjects.geojson_stream import stream_features

    path = tmp_path / "bad.geojson"
    path.write_text(text)
    with pytest.raises(DataError, match=message):
        stream_features(str(path))
    path.write_bytes(b'{"type": "FeatureCollection", "features": [{"id": "\xff"}]}')
    with pytest.raises(DataError, match="not a GeoJSON file"):
        stream_features(str(path))


@pytest.mark.parametrize("block", [1, 7, 8192])
def test_overlaps_found_block_by_block_are_every_pair_measured_at_once(monkeypatch, block):
    """check measures overlaps a block of pairs at a time: the same findings as measuring every pair of one metric
    projection, in file order."""
    from tollcli.geoobjects import check as geoobject_check
    from tollcli.spatial import metric_crs, project

    monkeypatch.setattr(geoobject_check, "OVERLAP_BLOCK", block)
    rng = np.random.default_rng(5)
    centres = np.column_stack([rng.uniform(2.0, 2.02, 60), rng.uniform(42.0, 42.02, 60)])
    wgs84 = shapely.buffer(shapely.points(centres), rng.uniform(0.0003, 0.002, 60))
    ids = [f"g{i}" for i in range(60)]
    found = [(f.feature, f.problem) for f in geoobject_check._overlaps(ids, wgs84, {"g0": {"g1"}})]
    metric = project(wgs84, metric_crs(wgs84))
    expected = []
    for i in range(60):
        for j in range(i + 1, 60):
            area = shapely.intersection(metric[i], metric[j]).area
            if area > 1.0 and not (i, j) == (0, 1):
                expected.append((ids[i], f"overlaps {ids[j]} ({area:.0f} m²)"))
    assert found == expected and len(expected) > 20


def test_a_store_damaged_inside_is_compiled_again(tmp_path, monkeypatch):
    """Bytes of a polygon changed on disk after the store was written: the manifest check finds them, the store is
    compiled again (one note on stderr) and the invoice is the one charged without a cache; a store changed after it
    was checked (in this process) is a one-line error naming it."""
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    store = geoobject_store.load_geoobjects(GEO).store
    wkb = np.load(store / "metric_wkb.npy")
    wkb[1:5] = 0xFF  # the first polygon's geometry type
    np.save(store / "metric_wkb.npy", wkb)
    drive = str(SAMPLES / "sim" / "urban-fault" / "drive.nmea")
    r = run_cli("process", drive, "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "i.json"), "-q")
    assert r.returncode == 0, r.stderr
    assert b"metric_wkb.npy differs from its digest): compiled again" in r.stderr and r.stderr.count(b"\n") == 1
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    assert run_cli("process", drive, "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "off.json"), "-q").returncode == 0
    assert (tmp_path / "i.json").read_bytes() == (tmp_path / "off.json").read_bytes()
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    geo = geoobject_store.load_geoobjects(GEO)  # checked and mapped; then changed under the mapping
    wkb = np.load(store / "metric_wkb.npy")
    wkb[1:5] = 0xFF
    with open(store / "metric_wkb.npy", "r+b") as fh:  # in place: the mapping sees it
        fh.seek(128)
        fh.write(wkb[:8].tobytes())
    with pytest.raises(DataError, match="metric_wkb.npy: damaged"):
        geo.polygons[0]


