"""What makes ``process`` fast and bounded: chunked reading, the compiled geo-object cache, the sealed invoice text.

None of these may change an invoice by a byte: every test compares against the
straightforward path.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from conftest import REPO, SAMPLES, run_cli
from scipy import stats

from tollcli.charging import geoobject_store, pipeline
from tollcli.charging.invoice import invoice_json, seal
from tollcli.charging.pipeline import ChargeSettings, charge_log
from tollcli.integrity import design
from tollcli.integrity.measurements import CONSTELLATION_LETTER, sv_labels

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")


@pytest.mark.parametrize("log", ["sim/urban-fault/drive.nmea", "sim/rural-fault/drive.nmea", "straight-drive.nmea"])
def test_chunk_size_does_not_change_the_invoice(monkeypatch, log):
    """Satellites, RAIM and geo-object pairs are done per chunk: 37-epoch chunks give the same bytes as one."""
    path = str(SAMPLES / log)
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 1_000_000)
    whole, _ = charge_log(path, GEO, TARIFF, ChargeSettings(), roads=ROADS)
    table_whole = []
    charge_log(path, GEO, TARIFF, ChargeSettings(), epoch_table=table_whole)
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 37)
    chunked, _ = charge_log(path, GEO, TARIFF, ChargeSettings(), roads=ROADS)
    table_chunked = []
    charge_log(path, GEO, TARIFF, ChargeSettings(), epoch_table=table_chunked)
    assert invoice_json(chunked) == invoice_json(whole)
    assert table_chunked[0].equals(table_whole[0])
    assert len(table_whole[0]) > 37 * 4


def test_compiled_geoobjects_are_the_parsed_ones(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    parsed = geoobject_store.load_geoobjects(GEO)
    files = list((tmp_path / "cache" / "geoobjects").glob("*.npz"))
    assert len(files) == 1
    compiled = geoobject_store.load_geoobjects(GEO)
    for name in ("ids", "names", "road_class", "hal_m"):
        assert np.array_equal(getattr(compiled, name), getattr(parsed, name))
    assert compiled.crs == parsed.crs
    assert (shapely.to_wkb(compiled.polygons) == shapely.to_wkb(parsed.polygons)).all()  # every coordinate bit
    # a damaged copy is parsed again, and replaced
    files[0].write_bytes(b"not an npz")
    again = geoobject_store.load_geoobjects(GEO)
    assert (shapely.to_wkb(again.polygons) == shapely.to_wkb(parsed.polygons)).all()
    assert files[0].stat().st_size > 100


def test_cache_off_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    geoobject_store.load_geoobjects(GEO)
    assert not any(tmp_path.rglob("*.npz"))


def test_cold_and_warm_cache_give_the_same_invoice(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    out = []
    for run in ("cold", "warm"):
        target = tmp_path / f"{run}.json"
        r = run_cli("process", str(SAMPLES / "sim" / "urban-fault" / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF,
                    "-o", str(target), "-q")  # fmt: skip
        assert r.returncode == 0, r.stderr
        out.append(target.read_bytes())
    assert out[0] == out[1]
    assert list((tmp_path / "cache").rglob("*.npz"))


def test_sealed_text_is_the_canonical_encoding():
    invoice, _ = charge_log(str(SAMPLES / "straight-drive.nmea"), GEO, TARIFF, ChargeSettings())
    text = invoice_json(invoice)
    assert text == json.dumps(dict(invoice), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
    assert pipeline.content_sha256(invoice) == invoice["content_sha256"]
    invoice["vehicle"] = "someone else"  # changing the invoice drops the kept text
    assert '"vehicle": "someone else"' in invoice_json(invoice)
    assert seal(json.loads(text)).text == text


def test_chi2_functions_are_scipy_stats_ones():
    """design uses scipy.special (fast to import) for χ²; the values are scipy.stats' to the bit."""
    rng = np.random.default_rng(3)
    dof = rng.integers(1, 40, 2000)
    p = 10 ** rng.uniform(-9, -1, 2000)
    x = rng.uniform(0, 150, 2000)
    assert np.array_equal(design.classic_threshold(p[0], dof), stats.chi2.isf(p[0], dof))
    assert np.array_equal(design.false_alarm_probability(x, dof), stats.chi2.sf(x, dof))


def test_stored_threshold_rows_are_the_computed_ones(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path))
    grid = np.arange(0.0, 5.0, 0.5)
    first = design._stored_row(1e-4, 0.5, grid, 6)
    assert list(tmp_path.rglob("*.npy"))
    again = design._stored_row(1e-4, 0.5, grid, 6)
    assert np.array_equal(first, again)
    assert np.array_equal(first, design.etc_threshold(1e-4, np.full(grid.shape, 6), grid**2))


def test_satellite_labels():
    const = np.array(["GPS", "Galileo", None, "weird", "GPS", "SBAS", "GLONASS"], dtype=object)
    svid = np.array([5, 11, 3, 7, 32, 131, 24])
    assert sv_labels(const, svid).tolist() == ["G05", "E11", "X03", "X07", "G32", "S131", "R24"]
    assert set(CONSTELLATION_LETTER.values()) >= {"G", "E", "R", "C", "J", "S"}


def test_lean_command_start_and_full_help():
    """``tollcli CMD`` builds only that command; ``tollcli --help`` still lists them all."""
    r = run_cli("--help")
    assert r.returncode == 0
    for name in ("process", "audit", "batch", "epochs", "geoobjects", "simulate", "verify"):
        assert name in r.stdout.decode()
    r = run_cli("process", "--help")
    assert r.returncode == 0 and "--geo" in r.stdout.decode()
    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.decode().startswith("tollcli ")
