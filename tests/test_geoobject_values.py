"""Odd but legal-looking geo-object files and JSON inputs (part of issue 55): a HAL of ``Infinity`` or 1e300 made every
position "within HAL" and wrote ``Infinity`` into the invoice (not JSON); ``"40"`` (text), a negative or a boolean HAL
passed, and so did lengths (what a per-km tariff prices) of ``Infinity``, text or below 0; a polygon 151° wide was never matched and never reported; an unclosed ring was closed silently; a JSON integer
of 5 000 digits ended in an internal error. Each is now refused in one line naming the file and the geo-object."""

from __future__ import annotations

import json

import pytest
from conftest import REPO, SAMPLES, run_cli

GEO = REPO / "geoobjects" / "example-geoobjects.geojson"
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
LOG = str(SAMPLES / "straight-drive.nmea")


def _edited(tmp_path, edit) -> str:
    doc = json.loads(GEO.read_text())
    edit(doc)
    path = tmp_path / "geo.geojson"
    path.write_text(json.dumps(doc))  # (json writes inf as Infinity, as a hostile file would)
    return str(path)


def _box(lon0, lat0, lon1, lat1):
    return {"type": "Polygon", "coordinates": [[[lon0, lat0], [lon1, lat0], [lon1, lat1], [lon0, lat1], [lon0, lat0]]]}


def _set_hal(value):
    return lambda doc: doc["features"][0]["properties"].__setitem__("hal_m", value)


def _add(feature_id, geometry):
    return lambda doc: doc["features"].append({"type": "Feature", "geometry": geometry,
                                               "properties": {"id": feature_id, "hal_m": 40, "road_class": "motorway"}})  # fmt: skip


def _unclose(doc):
    ring = doc["features"][0]["geometry"]["coordinates"][0]
    del ring[-1]


CASES = {
    "hal Infinity": (_set_hal(float("inf")), "not a HAL"),
    "hal 1e300": (_set_hal(1e300), "not a HAL"),
    "hal negative": (_set_hal(-5), "not a HAL"),
    "hal as text": (_set_hal("40"), "not a number"),
    "hal true": (_set_hal(True), "not a number"),
    "151 degrees wide": (_add("WIDE", _box(2.0, 40.0, 153.0, 45.0)), "no metric frame holds it"),
    "the world": (_add("WORLD", _box(-180.0, -90.0, 180.0, 90.0)), "no metric frame holds it"),
    "unclosed ring": (_unclose, "not closed"),
    "length Infinity": (lambda doc: doc["features"][0]["properties"].__setitem__("section_length_m", float("inf")), "not a length"),
    "length as text": (lambda doc: doc["features"][0]["properties"].__setitem__("length_m", "1200"), "not a length"),
    "negative tunnel": (lambda doc: doc["features"][0]["properties"].__setitem__("tunnel_m", -5), "not a length"),
    "road class a number": (lambda doc: doc["features"][0]["properties"].__setitem__("road_class", 7), "not a name"),
    "direction sideways": (lambda doc: doc["features"][0]["properties"].__setitem__("direction", "sideways"), "is none of"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_geoobject_the_tool_cannot_use_is_refused(tmp_path, case):
    edit, says = CASES[case]
    geo = _edited(tmp_path, edit)
    check = run_cli("geoobjects", "check", geo)
    assert check.returncode == 1 and says in check.stdout.decode() + check.stderr.decode(), check.stdout.decode()
    out = tmp_path / "i.json"
    done = run_cli("process", LOG, "--geo", geo, "--tariff", TARIFF, "-o", str(out), "-q")
    err = done.stderr.decode()
    assert done.returncode == 1 and says in err and len(err.strip().splitlines()) == 1 and not out.exists(), err


def test_the_example_network_still_passes():
    assert run_cli("geoobjects", "check", str(GEO)).returncode == 0


def test_a_json_integer_of_5000_digits_is_a_one_line_error(tmp_path):
    out = tmp_path / "i.json"
    assert run_cli("process", LOG, "--geo", str(GEO), "--tariff", TARIFF, "-o", str(out), "-q").returncode == 0
    text = out.read_text()
    at = text.index('"total"')
    bad = tmp_path / "bad.json"
    bad.write_text(text[:at] + '"x": ' + "2" * 5000 + ", " + text[at:])
    config = tmp_path / "config.json"
    config.write_text('{"parameters": {"tc": ' + "3" * 5000 + "}}")
    for args in (("verify", str(bad)), ("info", str(bad)),
                 ("process", LOG, "--config", str(config), "--geo", str(GEO), "--tariff", TARIFF, "-o", str(tmp_path / "c.json"), "-q")):  # fmt: skip
        done = run_cli(*args)
        err = done.stderr.decode()
        assert done.returncode in (1, 2) and "4300 digits" in err and len(err.strip().splitlines()) == 1, (args[0], err)


def test_a_road_file_on_mars_is_a_one_line_error(tmp_path):
    """A Shapefile whose .prj is a CRS of Mars: ``ProjError … not belong to the same celestial body`` (exit 5)."""
    import geopandas as gpd

    roads = gpd.read_file(REPO / "geoobjects" / "example-roads.geojson")
    shp = tmp_path / "roads.shp"
    roads.to_file(shp)
    shp.with_suffix(".prj").write_text('GEOGCS["Mars 2000",DATUM["D_Mars_2000",SPHEROID["Mars_2000_IAU_IAG",3396190.0,169.894447]],'
                                       'PRIMEM["Greenwich",0],UNIT["Decimal_Degree",0.0174532925199433]]')  # fmt: skip
    done = run_cli("geoobjects", "build", str(shp), "-o", str(tmp_path / "geo.geojson"), "-q")
    err = done.stderr.decode()
    assert done.returncode == 1 and "cannot be turned into WGS-84" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "geo.geojson").exists()


def test_a_feature_of_millions_of_vertices_is_refused_before_it_fills_memory(tmp_path, monkeypatch):
    """One ring of 10 million vertices (230 MB) took 44 s and 2.7 GB; a feature's text is now limited
    (``MAX_FEATURE_CHARS``, 64 MB: a 3.5 million-vertex ring is refused in 7 s at 630 MB). Here the limit is made small."""
    from tollcli.errors import DataError
    from tollcli.geoobjects import geojson_stream

    ring = [[2.9 + 1e-3 * (k % 7), 42.7 + 1e-6 * k] for k in range(20_000)]
    ring.append(ring[0])
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"id": "SMALL", "hal_m": 40}, "geometry": _box(2.90, 42.70, 2.91, 42.71)},
        {"type": "Feature", "properties": {"id": "BIG", "hal_m": 40}, "geometry": {"type": "Polygon", "coordinates": [ring]}}]}  # fmt: skip
    path = tmp_path / "big.geojson"
    path.write_text(json.dumps(doc))
    monkeypatch.setattr(geojson_stream, "MAX_FEATURE_CHARS", 100_000)
    with pytest.raises(DataError, match="longer than"):
        geojson_stream.stream_features(str(path))
    monkeypatch.setattr(geojson_stream, "MAX_FEATURE_CHARS", 10_000_000)
    assert len(geojson_stream.stream_features(str(path))[0]) == 2
