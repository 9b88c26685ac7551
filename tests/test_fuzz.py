"""Fuzzing: whatever the input, a result or a clear error — never an exception escaping.

Budget: ``FUZZ_EXAMPLES`` examples per fuzzer (default small, for CI);
``benchmarks/fuzz_nightly.py`` runs the same fuzzers with many more.
"""

from __future__ import annotations

import datetime as dt
import io
import json
import os
import tempfile

import numpy as np

from conftest import run_main
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tollcli.geoobjects.build import build_geoobjects, check_geoobjects
from tollcli.charging.recognition import load_geoobjects
from tollcli.charging.tariffs import load_tariff
from tollcli.errors import TollError
from tollcli.gnss.nmea_measurements import nmea_measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim
from tollcli.readers.nmea import compose, read_nmea

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), derandomize=EXAMPLES <= 200)

# ----------------------------------------------------------------------------------------------- NMEA
_tod = st.one_of(st.floats(0, 86_399.99), st.just(86_400.0), st.sampled_from([0.0, 86_399.0, 43_200.0]))  # 23:59:60 leap
_lat = st.one_of(st.floats(-90, 90), st.floats(-1000, 1000))
_lon = st.one_of(st.floats(-180, 180), st.floats(-1000, 1000))
_date = st.one_of(st.dates(dt.date(1980, 1, 6), dt.date(2099, 12, 31)), st.sampled_from([dt.date(2019, 4, 6), dt.date(1999, 8, 21)]))


def _safe(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except (ValueError, OverflowError):
        return "$GPTXT,01,01,02,unrepresentable*00"


_valid = st.one_of(
    st.builds(lambda t, la, lo: _safe(compose.gga, t, la, lo), _tod, _lat, _lon),
    st.builds(lambda t, la, lo, d: _safe(compose.rmc, t, la, lo, 10.0, 90.0, d), _tod, _lat, _lon, _date),
    st.builds(lambda t, d: _safe(compose.zda, t, d), _tod, _date),
    st.builds(lambda p: compose.gsa(p, 1.2, 0.8, 1.0, system_id=1), st.lists(st.integers(1, 437), max_size=14)),
    st.builds(lambda s: "\n".join(compose.gsv(s)), st.lists(st.tuples(st.integers(1, 437), st.floats(-5, 95), st.floats(0, 365), st.floats(0, 60)), max_size=9)),
    st.builds(lambda t, r: compose.grs(t, r), _tod, st.lists(st.floats(-1e6, 1e6), max_size=12)),
    st.builds(lambda t: compose.gst(t, 2.0, 3.0, 2.0, 10.0, 2.0, 2.0, 3.0), _tod),
)  # fmt: skip
_field = st.sampled_from(["", "nan", "inf", "-inf", "1e999", "NaN", "-0", "99999999999", "x" * 5000, "12.3.4", "ÿ", "-", ","])


def _mutate(line: str, how: int, pos: int, junk: str) -> str:
    pos = pos % (len(line) + 1)
    if how == 0:
        return line[:pos]  # truncated
    if how == 1:
        return line[:-2] + "00" if len(line) > 3 else line  # wrong checksum
    if how == 2:
        return line[:pos] + junk + line[pos:]  # noise inside
    if how == 3:
        body = line[1:].split("*")[0].split(",")
        body[pos % len(body)] = junk  # a field replaced, checksum recomputed: decodes, then must be judged
        return compose.with_checksum(",".join(body))
    return junk + line  # binary before the sentence


_mutated = st.builds(_mutate, _valid, st.integers(0, 4), st.integers(0, 200), st.one_of(_field, st.binary(max_size=40).map(lambda b: b.decode("latin-1"))))
_line = st.one_of(_valid, _mutated, st.binary(max_size=80).map(lambda b: b.decode("latin-1")), st.just("# comment"))


@FUZZ
@given(st.lists(_line, max_size=60), st.booleans())
def test_fuzz_nmea_logs_read_and_check_without_exceptions(lines, shuffle_time):
    text = "\n".join(reversed(lines) if shuffle_time else lines)  # backwards timestamps too
    try:
        tables = read_nmea(io.BytesIO(text.encode("latin-1", "replace")))
    except TollError:
        return  # a clear, documented error (e.g. gzip magic bytes that are not gzip)
    assert len(tables.epochs) == tables.stats.epochs
    out = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc", fde=True))
    assert len(out) == len(tables.epochs)


#: the fuzzed inputs through every command: fewer examples than the library fuzzers (each runs eight commands)
FUZZ_CLI = settings(max_examples=max(EXAMPLES // 4, 5), deadline=None, suppress_health_check=list(HealthCheck),
                    derandomize=EXAMPLES <= 200)  # fmt: skip
#: exit codes the commands document (0 ok, 1 data, 2 usage, 3 partial); 4 (system) and 5 (internal) are defects here
DOCUMENTED = {0, 1, 2, 3}
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GEO = os.path.join(ROOT, "geoobjects", "example-geoobjects.geojson")
TARIFF = os.path.join(ROOT, "geoobjects", "example-tariff.toml")
DRIVE = os.path.join(ROOT, "samples", "sim", "rural-clean", "drive.nmea")


def _written(folder: str, name: str, text) -> str:
    """``text`` (JSON for a non-string) written to ``folder/name``; its path."""
    path = os.path.join(folder, name)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text if isinstance(text, str) else json.dumps(text))
    return path


def _judged(code: int, err: str, what: str, output: str | None = None, parse=None) -> None:
    """A documented exit, no traceback; an error (1, 2) in one line that says so and no output left behind; a
    success (0, 3) whose ``output`` is there and parses (``parse``: the reader that must take it)."""
    assert code in DOCUMENTED and "Traceback" not in err, f"{what}: exit {code}: {err}"
    if code:
        assert err.strip(), f"{what}: exit {code} without a word"
    if code in (1, 2):
        assert err.strip().splitlines()[-1].startswith("tollcli: error"), f"{what}: exit {code}: {err}"
        if output is not None:
            assert not os.path.exists(output), f"{what}: exit {code} left {output} behind"
    elif output is not None and parse is not None:
        assert os.path.exists(output), f"{what}: exit {code} wrote no {output}"
        parse(output)


def _parses_as_invoice(path: str) -> None:
    """An invoice that parses and whose content hash is its content's."""
    from tollcli.job.pipeline import content_sha256

    with open(path, encoding="utf-8") as fh:
        invoice = json.load(fh)
    assert invoice["content_sha256"] == content_sha256(invoice)
    assert all(line["evidence"] for line in invoice["lines"])  # every charge explained by positions


def _parses_as_json(path: str) -> None:
    with open(path, encoding="utf-8") as fh:
        json.load(fh)


def _parses_as_table(path: str) -> None:
    import pandas as pd

    (pd.read_parquet if path.endswith(".parquet") else pd.read_csv)(path)


@FUZZ_CLI
@given(st.lists(_line, max_size=40))
def test_fuzz_logs_through_every_command(lines):
    """A fuzzed log through every command that reads a log (and verify of what process wrote): a documented exit."""
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "log.nmea")
        with open(log, "w", encoding="latin-1", errors="replace") as fh:
            fh.write("\n".join(lines))
        out = {k: os.path.join(tmp, name) for k, name in (("e", "e.parquet"), ("i", "i.csv"), ("c", "c.csv"), ("f", "f.json"),
                                                          ("l", "l.csv"), ("inv", "inv.json"))}  # fmt: skip
        runs = {
            "epochs": (["epochs", log, "-q", "-o", out["e"], "--satellites", os.path.join(tmp, "s.parquet")], out["e"], _parses_as_table),
            "integrity": (["integrity", log, "-q", "-o", out["i"]], out["i"], _parses_as_table),
            "integrity --checks": (["integrity", log, "--checks", "-q", "-o", out["c"]], out["c"], _parses_as_table),
            "findings": (["findings", log, "--geo", GEO, "-q", "-o", out["f"]], out["f"], _parses_as_json),
            "locate": (["locate", log, "-q", "-o", out["l"]], out["l"], _parses_as_table),
            "process": (["process", log, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", out["inv"]], out["inv"], _parses_as_invoice),
            "batch": (["batch", log, "--geo", GEO, "--tariff", TARIFF, "--workers", "1", "-q", "-o", os.path.join(tmp, "out")], None, None),
        }  # fmt: skip
        for what, (args, output, parse) in runs.items():
            code, err = run_main(*args)
            _judged(code, err, what, output, parse)
            if what == "process" and code == 0:
                _judged(*run_main("verify", os.path.join(tmp, "inv.json")), "verify")


@FUZZ_CLI
@given(st.deferred(lambda: _doc))
def test_fuzz_geoobject_files_through_the_commands(doc):
    """A fuzzed geo-object file through geoobjects check and process: a documented exit, never a traceback."""
    with tempfile.TemporaryDirectory() as tmp:
        path = _written(tmp, "g.geojson", doc)
        _judged(*run_main("geoobjects", "check", path, "-q"), "geoobjects check")
        _judged(*run_main("process", DRIVE, "--geo", path, "--tariff", TARIFF, "-q", "-o", os.path.join(tmp, "i.json")), "process")


@FUZZ_CLI
@given(st.deferred(lambda: st.one_of(_tariff, _per_km_tariff)))
def test_fuzz_tariffs_through_process(text):
    """A fuzzed tariff through process: an invoice or a documented exit with a reason, never a traceback."""
    with tempfile.TemporaryDirectory() as tmp:
        path = _written(tmp, "t.toml", text)
        _judged(*run_main("process", DRIVE, "--geo", GEO, "--tariff", path, "-q", "-o", os.path.join(tmp, "i.json")), "process")


# ------------------------------------------------------------------------------------------ GeoJSON
_coord = st.one_of(st.tuples(st.floats(-200, 200), st.floats(-100, 100)).map(list), st.just([]), st.just(["a", "b"]),
                   st.just([float("nan"), 1.0]), st.tuples(st.floats(2.9, 2.91), st.floats(42.7, 42.71)).map(list))  # fmt: skip
_ring = st.lists(_coord, max_size=6)
_geometry = st.one_of(
    st.builds(lambda c: {"type": "LineString", "coordinates": c}, _ring),
    st.builds(lambda r: {"type": "Polygon", "coordinates": [r]}, _ring),
    st.builds(lambda r: {"type": "Polygon", "coordinates": [r + r[:1]]}, _ring),
    st.builds(lambda c: {"type": "Point", "coordinates": c}, _coord),
    st.just({"type": "Polygon", "coordinates": []}), st.just({"type": "Nonsense"}), st.just(None), st.just({}),
    st.just({"type": "Polygon", "coordinates": [[[2.9, 42.7], [2.91, 42.71], [2.91, 42.7], [2.9, 42.71], [2.9, 42.7]]]}),
    st.just({"type": "LineString", "coordinates": [[0.0, 0.0], [0.0, 0.0]]}),  # found by the nightly run: zero length
)  # fmt: skip
_props = st.one_of(
    st.just({}), st.fixed_dictionaries({"id": st.one_of(st.text(max_size=5), st.integers(), st.none())},
                                       optional={"hal_m": st.one_of(st.floats(allow_nan=True), st.text(max_size=3), st.none()),
                                                 "tolled": st.one_of(st.booleans(), st.text(max_size=3)),
                                                 "road_class": st.text(max_size=5)}),
)  # fmt: skip
_feature = st.builds(lambda g, p: {"type": "Feature", "geometry": g, "properties": p}, _geometry, _props)
_doc = st.one_of(
    st.builds(lambda f: {"type": "FeatureCollection", "features": f}, st.lists(_feature, max_size=6)),
    st.builds(lambda f, c: {"type": "FeatureCollection", "features": f, "crs": {"type": "name", "properties": {"name": c}}},
              st.lists(_feature, max_size=3), st.sampled_from(["EPSG:3857", "urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:4326"])),
    st.just([]), st.just({"type": "Feature"}), st.text(max_size=20),
)  # fmt: skip


@FUZZ
@given(_doc)
def test_fuzz_geoobject_files_give_results_or_data_errors(doc):
    with tempfile.TemporaryDirectory() as tmp:
        path = _written(tmp, "g.geojson", doc)
        for fn in (build_geoobjects, check_geoobjects, load_geoobjects):
            try:
                result = fn(path)
            except TollError as exc:  # refused: one line that names the file
                assert path in str(exc) and "\n" not in str(exc), f"{fn.__name__}: {exc}"
                continue
            if fn is build_geoobjects:  # built: polygons of finite coordinates, each with an id and a positive HAL
                for feature in result["features"]:
                    assert feature["geometry"]["type"] in ("Polygon", "MultiPolygon")
                    assert np.isfinite(np.array(_flat_coordinates(feature["geometry"]["coordinates"]), float)).all()
                    assert feature["properties"]["id"] not in (None, "") and feature["properties"]["hal_m"] > 0
            elif fn is load_geoobjects:  # loaded: as many distinct ids as geo-objects
                assert len(set(result.ids)) == len(result.ids)


def _flat_coordinates(coords) -> list:
    """Every number of nested GeoJSON coordinates."""
    if isinstance(coords, (int, float)):
        return [coords]
    return [x for c in coords for x in _flat_coordinates(c)]


# ------------------------------------------------------------------------------------------- tariffs
_toml_value = st.one_of(st.integers(-5, 10**6).map(str), st.decimals(allow_nan=False, allow_infinity=False, places=3).map(str),
                        st.text(alphabet="abc0123456789:", max_size=6).map(json.dumps), st.just("nan"), st.just("inf"),
                        st.just("true"), st.just("[1, 2]"), st.just("{a = 1}"))  # fmt: skip
_key = st.text(alphabet="abcdefghij_-", min_size=1, max_size=6)
_section = st.builds(lambda head, kvs: f"[{head}]\n" + "".join(f"{k} = {v}\n" for k, v in kvs),
                     st.one_of(_key.map(lambda k: f"road_class.{k}"), _key.map(lambda k: f'geoobject."{k}"'), _key),
                     st.lists(st.tuples(_key, _toml_value), max_size=4))  # fmt: skip
_band = st.builds(lambda s, e, f, d: f'[[band]]\nstart = "{s}"\nend = "{e}"\nfactor = {f}\n' + (f"days = {d}\n" if d else ""),
                  st.sampled_from(["07:00", "25:00", "22:00", "x", "00:00"]), st.sampled_from(["09:00", "06:00", "07:00", ""]),
                  _toml_value, st.sampled_from(["", '["mon"]', '["funday"]', "3"]))  # fmt: skip
_tariff = st.builds(lambda cur, tz, parts, junk: f"currency = {cur}\ntimezone = {tz}\n" + "".join(parts) + junk,
                    st.sampled_from(['"EUR"', '"E"', "1", '"€€€"']), st.sampled_from(['"Europe/Paris"', '"UTC"', '"Nowhere/X"', "5"]),
                    st.lists(st.one_of(_section, _band), max_size=5), st.sampled_from(["", "= broken", "[x", "\x00"]))  # fmt: skip


def _mostly(good, bad):
    """``good`` 39 times in 40, else ``bad``: many fuzzed tariffs load, so pricing is fuzzed too."""
    return st.sampled_from(range(40)).flatmap(lambda k: bad if k == 39 else good)


_values = _mostly(st.lists(st.sampled_from(["euro5", "euro6", "2", "5+"]), min_size=1, max_size=3, unique=True).map(json.dumps),
                  st.sampled_from(['"euro6"', "5", '["x"]', "true", "{a = 1}", "[]"]))  # fmt: skip
_vehicle = st.builds(lambda extra: '[vehicle]\neuro_class = ["euro5", "euro6"]\naxles = ["2", "5+"]\n' + extra,
                     _mostly(st.just(""), st.sampled_from(['vehicle_class = ["truck"]\n', "per_km = [1]\n", '1x = ["a"]\n'])))  # fmt: skip
_amount = _mostly(st.decimals(0, 10, places=4).map(str), _toml_value)
_filter = _mostly(st.one_of(
    st.tuples(st.just("euro_class"), _mostly(st.lists(st.sampled_from(["euro5", "euro6"]), min_size=1, unique=True).map(json.dumps), _values)),
    st.tuples(st.just("axles"), _mostly(st.lists(st.sampled_from(["2", "5+"]), min_size=1, unique=True).map(json.dumps), _values)),
    st.tuples(st.just("road_class"), _mostly(st.sampled_from(['"motorway"', '["motorway", "trunk"]', '"trunk"']), _values)),
    st.tuples(st.just("geoobject"), _mostly(st.sampled_from(['"g"', '"h"']), _values)),
    st.tuples(st.just("per_passage"), _amount),
    st.tuples(st.just("component"), _mostly(st.sampled_from(['"air"', '"noise"']), _values))),
    st.tuples(st.sampled_from(["zzz", "vehicle_class"]), _amount))  # fmt: skip
_rate = st.builds(lambda amount, kvs: f"[[table.rate]]\nper_km = {amount}\n" + "".join(f"{k} = {v}\n" for k, v in kvs),
                  _amount, st.lists(_filter, max_size=2, unique_by=lambda kv: kv[0]))  # fmt: skip
_table = st.builds(lambda start, until, rates: f"[[table]]\nvalid_from = {start}\n" + (f"valid_until = {until}\n" if until else "") + "".join(rates),
                   _mostly(st.sampled_from(["2024-01-01", "2024-07-01T00:00:00", "2024-07-01T00:00:00+02:00"]), st.just('"soon"')),
                   _mostly(st.just(""), st.sampled_from(["2024-09-01", "2023-01-01"])), st.lists(_rate, min_size=1, max_size=3))  # fmt: skip
_per_km_tariff = st.builds(lambda cur, vehicle, tables, lengths: f"{cur}\ntimezone = \"Europe/Berlin\"\n{vehicle}" + "".join(tables) + lengths,
                           st.sampled_from(['currency = "EUR"', 'currency = "JPY"\nminor_unit = 0']), _vehicle,
                           st.lists(_table, min_size=1, max_size=2),
                           _mostly(st.sampled_from(["", '[length_km]\n"g" = 1.5\n']), st.just("[length_km]\ng = -1\n")))  # fmt: skip


@FUZZ
@given(_per_km_tariff, st.dictionaries(st.sampled_from(["euro_class", "axles", "vehicle_class"]), st.sampled_from(["euro5", "euro6", "2", "5+", "truck"])),
       st.sampled_from([None, float("nan"), 0.0, 1234.5, 1e7]), st.datetimes(dt.datetime(2023, 1, 1), dt.datetime(2025, 1, 1)))
def test_fuzz_per_km_tariffs_give_prices_or_data_errors(text, vehicle, length_m, when):
    """A fuzzed per-km tariff, vehicle and length: a price ≥ 0 with a length when it charges per km, or a DataError."""
    with tempfile.TemporaryDirectory() as tmp:
        path = _written(tmp, "t.toml", text)
        try:
            tariff = load_tariff(path)
            price = tariff.price("g", "motorway", length_m, {"vehicle_class": "truck", **vehicle}, when.replace(tzinfo=dt.timezone.utc))
        except TollError:
            return
        assert price.fee >= 0 and (price.per_km == 0 or price.length_km is not None)


@FUZZ
@given(_tariff, _key, _key, st.datetimes(dt.datetime(1990, 1, 1), dt.datetime(2090, 1, 1)))
def test_fuzz_tariffs_give_fees_or_data_errors(text, road_class, vehicle_class, when):
    with tempfile.TemporaryDirectory() as tmp:
        path = _written(tmp, "t.toml", text)
        try:
            tariff = load_tariff(path)
            fee, _ = tariff.fee("g", road_class, vehicle_class, when.replace(tzinfo=dt.timezone.utc))
            assert fee >= 0
        except TollError:
            pass
