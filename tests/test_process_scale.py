"""What makes ``process`` fast and bounded: chunked reading, the compiled geo-object cache, the sealed invoice text.

None of these may change an invoice by a byte: every test compares against the
straightforward path.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import shapely
from conftest import REPO, SAMPLES, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from tollcli.geoobjects import store as geoobject_store
from tollcli.charging.canonical_json import canonical_json
from tollcli.charging.invoice import invoice_json, seal
from tollcli.charging.recognition import inside_pairs, load_geoobjects
from tollcli.enforcement.trip import cn0_summary
from tollcli.gnss import nmea_measurements
from tollcli.gnss.measurements import CONSTELLATION_LETTER, sv_labels
from tollcli.gnss.wls import wls_geometry
from tollcli.integrity import design
from tollcli.integrity.raim import RaimParams
from tollcli.job import pipeline
from tollcli.job.pipeline import ChargeSettings, charge_log
from tollcli.readers.nmea import read_nmea

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
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 2048)  # chunks end at block ends
    chunked, _ = charge_log(path, GEO, TARIFF, ChargeSettings(), roads=ROADS)
    table_chunked = []
    charge_log(path, GEO, TARIFF, ChargeSettings(), epoch_table=table_chunked)
    assert invoice_json(chunked) == invoice_json(whole)
    assert table_chunked[0].equals(table_whole[0])
    assert len(table_whole[0]) > 37 * 4


def _same_geoobjects(a, b) -> None:
    for name in ("ids", "names", "road_class", "hal_m", "length_m", "tunnel_m", "gap_m", "frame", "n_parts"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.crs == b.crs and a.frames == b.frames
    assert (shapely.to_wkb(a.polygons.all()) == shapely.to_wkb(b.polygons.all())).all()  # every coordinate bit
    assert np.array_equal(a.index.bounds, b.index.bounds)


def test_compiled_geoobjects_are_the_parsed_ones(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    parsed = geoobject_store.load_geoobjects(GEO)
    assert parsed.store is None
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path / "cache"))
    first = geoobject_store.load_geoobjects(GEO)
    stores = list((tmp_path / "cache" / "geoobjects").glob(f"*.v{geoobject_store.STORE_FORMAT}"))
    assert stores == [first.store]
    mapped = geoobject_store.load_geoobjects(GEO)
    assert isinstance(mapped.hal_m, np.memmap) and isinstance(mapped.polygons.wkb, np.memmap)  # mapped, not read
    _same_geoobjects(mapped, parsed)
    assert mapped.source_sha256 == parsed.source_sha256 == pipeline.file_sha256(GEO)
    # a damaged store is compiled again, and replaced
    (stores[0] / "metric_wkb.npy").write_bytes(b"not an array")
    again = geoobject_store.load_geoobjects(GEO)
    _same_geoobjects(again, parsed)
    assert (stores[0] / "metric_wkb.npy").stat().st_size > 1000


def test_a_store_cut_short_is_compiled_again(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path))
    store = geoobject_store.load_geoobjects(GEO).store
    wkb = np.load(store / "metric_wkb.npy")
    np.save(store / "metric_wkb.npy", wkb[: len(wkb) // 2])
    _same_geoobjects(geoobject_store.load_geoobjects(GEO), geoobject_store.geoobjects_from_columns(geoobject_store.compile_file(GEO)[0]))


def test_cache_off_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", "off")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    geoobject_store.load_geoobjects(GEO)
    assert not any(tmp_path.rglob("*"))


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
    assert list((tmp_path / "cache").rglob("*.npy"))


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


# --- the faster pieces of process, each against the straightforward computation it replaced ---


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**20), 10**20) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.tuples(inner, inner) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=30,
)  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(json_values)
def test_canonical_json_is_json_dumps_indented_sorted(value):
    try:
        expected = json.dumps(value, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False)
    except ValueError:  # a NaN or an infinity: not JSON, refused by both
        with pytest.raises(ValueError):
            canonical_json(value)
        return
    assert canonical_json(value) == expected


def test_canonical_json_of_a_real_invoice_and_unusual_values():
    invoice, _ = charge_log(str(SAMPLES / "straight-drive.nmea"), GEO, TARIFF, ChargeSettings())
    body = dict(invoice)
    assert canonical_json(body) == json.dumps(body, indent=2, sort_keys=True, ensure_ascii=False)
    odd = {"a": np.float64(1.5), "b": [True, np.float64("2.5")], "c": {"é": "\n\"\u2028"}}
    int_keys = {3: "int key", 10: [1]}  # left to json.dumps
    for value in (odd, int_keys):
        assert canonical_json(value) == json.dumps(value, indent=2, sort_keys=True, ensure_ascii=False)
    for not_json in ({"hal_m": float("inf")}, {"b": [np.float64("nan")]}, {3: -float("inf")}):  # an invoice is JSON
        with pytest.raises(ValueError, match="not JSON compliant"):
            canonical_json(not_json)
    with pytest.raises(TypeError):  # what json.dumps refuses, it still refuses
        canonical_json({"x": np.int64(3)})


def test_latest_angles_per_satellite_are_groupby_last():
    rng = np.random.default_rng(5)
    for trial in range(200):
        n = int(rng.integers(1, 60))
        t_s = rng.integers(0, 10, n).astype(float)
        known = pd.DataFrame({"t_s": np.sort(t_s) if trial % 2 else t_s,  # a log's rows are in time: its own path
                              "constellation": rng.choice(np.array(["GPS", "Galileo", None, "BeiDou"], dtype=object), n),
                              "svid": rng.integers(1, 5, n).astype(np.int64), "elev_deg": rng.random(n), "azim_deg": rng.random(n)})  # fmt: skip
        expected = known.sort_values("t_s", kind="stable").groupby(["constellation", "svid"], as_index=False).last()
        rows = nmea_measurements._latest_rows(known["t_s"].to_numpy(), known["constellation"].to_numpy(), known["svid"].to_numpy())
        got = known.iloc[rows][expected.columns].reset_index(drop=True)
        pd.testing.assert_frame_equal(got, expected, check_dtype=False)
        arrow = pd.array(known["constellation"].to_numpy(), dtype="string[pyarrow]")  # the reader's strings: the same rows
        assert np.array_equal(nmea_measurements._latest_rows(known["t_s"].to_numpy(), arrow, known["svid"].to_numpy()), rows)
        named = known[known["constellation"].notna()]  # a column without a missing name: coded once, picked by code
        coded = nmea_measurements._arrow_coded(pd.Series(pd.array(named["constellation"].to_numpy(), dtype="string[pyarrow]")))
        by_name = nmea_measurements._latest_rows(named["t_s"].to_numpy(), named["constellation"].to_numpy(), named["svid"].to_numpy())
        by_code = nmea_measurements._latest_rows(named["t_s"].to_numpy(), coded[0], named["svid"].to_numpy())
        assert np.array_equal(by_code, by_name) and np.array_equal(coded[1][coded[0][by_code]], named["constellation"].to_numpy()[by_name])


def test_first_of_each_satellite_is_drop_duplicates():
    rng = np.random.default_rng(6)
    for svid_max in (40, 70_000):  # the second takes the general path
        n = 500
        t = pd.DataFrame({"epoch": rng.integers(0, 20, n), "constellation": rng.choice(np.array(["GPS", "Galileo", None], dtype=object), n),
                          "svid": rng.integers(0, svid_max, n) % 7})  # fmt: skip
        rows = nmea_measurements._first_of_each(t["epoch"].to_numpy(np.int64), t["constellation"].to_numpy(), t["svid"].to_numpy(np.int64))
        assert rows.tolist() == np.flatnonzero(~t.duplicated(["epoch", "constellation", "svid"]).to_numpy()).tolist()


def test_cn0_summary_against_pandas_groupby():
    rng = np.random.default_rng(8)
    for _ in range(100):
        m = int(rng.integers(0, 300))
        sats = pd.DataFrame({"epoch": rng.integers(95, 130, m),
                             "cn0_dbhz": np.where(rng.random(m) < 0.1, np.nan, np.round(rng.uniform(-5, 50, m), 1))})  # fmt: skip
        got = cn0_summary(sats, 30, 100)
        s = sats[np.isfinite(sats["cn0_dbhz"]) & (sats["cn0_dbhz"] > 0)]
        g = s.groupby(s["epoch"] - 100)["cn0_dbhz"]
        want = pd.DataFrame({"n_tracked": g.size(), "cn0_median": g.median(), "cn0_p80": g.quantile(0.8), "cn0_std": g.std(ddof=0)})
        want = want.reindex(range(30))
        assert got["n_tracked"].tolist() == want["n_tracked"].fillna(0).astype(int).tolist()
        for col in ("cn0_median", "cn0_p80", "cn0_std"):
            np.testing.assert_allclose(got[col], want[col], rtol=1e-13, atol=1e-13, err_msg=col)
        assert np.array_equal(got["cn0_median"], want["cn0_median"], equal_nan=True)  # order statistics: exact


def test_stored_p_fa_rows_are_those_of_the_thresholds(tmp_path, monkeypatch):
    monkeypatch.setenv("TOLLCLI_CACHE_DIR", str(tmp_path))
    table = design.EtcThresholdTable(5e-5, step=0.5, sqrt_lambda_max=20.0)
    dof = np.array([0, 1, 3, 3, 8, 12, 5])
    lam = np.array([4.0, 9.0, 0.0, 100.0, 1e6, np.nan, 30.0])
    assert np.array_equal(table.p_fa(dof, lam), design.false_alarm_probability(table(dof, lam), dof), equal_nan=True)
    assert len(list(tmp_path.rglob("etc-pfa-*.npy"))) == 4  # k = 1, 3, 5, 8 (not 12: its λ is NaN)


def test_process_does_not_import_scipy_special_with_cached_rows(tmp_path):
    """The χ² functions are only needed to build the cached rows: a second process imports no scipy.special."""
    code = ("import sys\nfrom tollcli.job.pipeline import ChargeSettings, charge_log\n"
            f"charge_log({str(SAMPLES / 'straight-drive.nmea')!r}, {GEO!r}, {TARIFF!r}, ChargeSettings())\n"
            "print('scipy.special' in sys.modules)\n")  # fmt: skip
    env = {**os.environ, "TOLLCLI_CACHE_DIR": str(tmp_path)}
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert first.stdout.strip() == "True" and second.stdout.strip() == "False"


def test_shared_geometry_gives_the_same_pairs():
    """inside_pairs with the chunk's WLS geometry (computed once) = recomputing it for the pairs' epochs."""
    tables = read_nmea(SAMPLES / "sim" / "urban-fault" / "drive.nmea")
    meas = nmea_measurements.nmea_measurements(tables.epochs, tables.satellites)
    geo = load_geoobjects(GEO)
    params = RaimParams(fde=True)
    shared = inside_pairs(tables.epochs, meas, geo, params, geometry=wls_geometry(meas.H, meas.sigma_m, meas.mask))
    alone = inside_pairs(tables.epochs, meas, geo, params)
    assert shared["epoch_row"].size > 0
    for k in alone:
        a, b = alone[k], shared[k]
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), k
