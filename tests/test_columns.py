"""The readers' tables as numpy columns (:mod:`tollcli.io.columns`): written to the same bytes as the DataFrames they
become, the same DataFrames as before, and ``epochs`` and ``info`` never import pandas."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from conftest import REPO, SHARED_DATA, shared

from tollcli.io.columns import Columns, as_columns
from tollcli.io.log_run import LogRun
from tollcli.io.writers import TableWriter
from tollcli.readers.navigation import iter_epoch_tables

GPSD_LOGS = sorted((SHARED_DATA / "gpsd").glob("*.log")) if (SHARED_DATA / "gpsd").exists() else []
OTHER_KINDS = [SHARED_DATA / "osnma" / "ublox" / "current_config.ubx"]  # u-blox NAV messages: the NAV table builder


def _tables(log: Path) -> list:
    with LogRun(str(log)) as run:
        try:
            return list(iter_epoch_tables(run))
        except Exception:  # noqa: BLE001 - a log the reader refuses has no table to compare
            return []


def _written(tmp_path: Path, name: str, chunks: list, fmt: str) -> bytes:
    path = tmp_path / f"{name}.{fmt}"
    with TableWriter(str(path), fmt) as w:
        for chunk in chunks:
            w.write(chunk)
        w.commit()
    return path.read_bytes()


def test_columns_are_of_one_length():
    with pytest.raises(ValueError, match="different lengths"):
        Columns({"a": np.zeros(2), "b": np.zeros(3)})
    assert len(Columns({})) == 0


def test_to_pandas_and_back_keeps_every_value():
    t = Columns({"epoch": np.arange(3, dtype=np.int64), "time_utc": np.array(["2024-05-01T12:00:00.250", "NaT", "2024-05-01T12:00:02"], dtype="datetime64[ms]"),
                 "mode": np.array(["A", None, "D"], dtype=object), "x_m": np.array([1.5, np.nan, -0.0]), "ok": np.array([True, False, True])})  # fmt: skip
    frame = t.to_pandas()
    assert str(frame["time_utc"].dtype) == "datetime64[ms, UTC]"
    assert frame["mode"].isna().tolist() == [False, True, False]
    back = as_columns(frame)
    assert back.columns == t.columns
    for name in t:
        a, b = t[name], back[name]
        if a.dtype == object:
            assert a.tolist() == b.tolist()
        else:
            np.testing.assert_array_equal(a, b)
            assert a.dtype == b.dtype


@pytest.mark.skipif(not GPSD_LOGS, reason="needs ../shared/data/gpsd")
@pytest.mark.parametrize("fmt", ["csv", "json", "geojson", "geojsonseq"])
def test_every_real_log_writes_the_same_bytes_from_columns_as_from_its_frame(tmp_path, fmt):
    """Both tables of every real log as CSV and JSON (every fourth log as GeoJSON and its sequence: the JSON rows
    with a point each): the same bytes from the columns as from the DataFrames they become."""
    logs = GPSD_LOGS if fmt in ("csv", "json") else GPSD_LOGS[::4]
    compared = 0
    for log in logs + [p for p in OTHER_KINDS if p.exists()]:
        chunks = _tables(log)
        if not chunks:
            continue
        for table in ("epoch", "satellite"):
            columns = [getattr(c, f"{table}_columns") for c in chunks]
            frames = [getattr(c, f"{table}s") for c in chunks]
            assert all(isinstance(c, Columns) for c in columns)
            assert _written(tmp_path, "columns", columns, fmt) == _written(tmp_path, "frame", frames, fmt), f"{log.name} {table} {fmt}"
            compared += 1
    assert compared >= 2 * len(logs) * 0.6  # 117 of the 177 logs give tables (the rest are binary protocols the reader refuses)


@pytest.mark.skipif(not GPSD_LOGS, reason="needs ../shared/data/gpsd")
def test_parquet_from_columns_holds_the_frames_columns_types_and_values(tmp_path):
    for log in GPSD_LOGS[::7]:
        chunks = _tables(log)
        if not chunks:
            continue
        for table in ("epoch", "satellite"):
            _written(tmp_path, "columns", [getattr(c, f"{table}_columns") for c in chunks], "parquet")
            _written(tmp_path, "frame", [getattr(c, f"{table}s") for c in chunks], "parquet")
            a, b = pq.read_table(tmp_path / "columns.parquet"), pq.read_table(tmp_path / "frame.parquet")
            assert a.schema.remove_metadata() == b.schema.remove_metadata(), log.name
            assert a.equals(b.replace_schema_metadata(None)), log.name
            back = pd.read_parquet(tmp_path / "columns.parquet")  # without pandas' metadata: text comes back as pandas' default str
            pd.testing.assert_frame_equal(back, pd.concat([getattr(c, f"{table}s") for c in chunks], ignore_index=True), check_dtype=False)


HEAVY = ("pandas", "scipy", "matplotlib", "tollcli.simulate", "tollcli.integrity", "tollcli.charging", "pydantic")


@pytest.mark.parametrize("command", [["epochs", "{log}", "-o", "{out}.csv", "-q", "--satellites", "{out}.sat.parquet"],
                                     ["epochs", "{log}", "-o", "{out}.geojson", "-q"], ["info", "{log}"], ["info", "--json", "{log}"]])  # fmt: skip
@pytest.mark.parametrize("log", ["ublox-zed-f9p-nmea.log", "bu353s4.log"])
def test_epochs_and_info_of_an_nmea_log_import_no_pandas(tmp_path, command, log):
    path = shared("gpsd", log)
    args = [a.format(log=path, out=tmp_path / "t") for a in command]
    probe = ("import sys\nfrom tollcli.cli.main import main\ncode = 0\ntry:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    code = e.code\n"
             f"print('exit:', code, 'imported:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))\n")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, cwd=REPO, timeout=120)
    tail = r.stdout.rsplit("exit:", 1)[1]
    assert tail.split()[0] in ("0", "None"), r.stderr
    imported = tail.split("imported:", 1)[1].strip()
    assert imported == "", f"tollcli {' '.join(command)} imported {imported}"


@pytest.mark.parametrize("seed", range(5))
def test_text_of_codes_is_the_string_array_of_the_names(seed):
    """A status column made from its codes equals ``pd.array`` of the names the codes index (negative codes from the
    end, as numpy indexes), dtype included; a code outside the names is refused, as numpy's indexing refuses it."""
    import pandas as pd

    from tollcli.io.columns import text_of_codes

    rng = np.random.default_rng(seed)
    names = ("valid", "fault", "unavailable", "", "probable_false_alarm")[: int(rng.integers(1, 6))]
    codes = rng.integers(-len(names), len(names), int(rng.integers(0, 300))).astype(rng.choice([np.int8, np.int64]))
    want = pd.array(np.asarray(names, dtype=object)[codes], dtype="string")
    got = text_of_codes(codes, names)
    assert got.dtype == want.dtype
    pd.testing.assert_extension_array_equal(got, want)
    with pytest.raises(IndexError):
        text_of_codes(np.array([len(names)]), names)
    with pytest.raises(IndexError):
        text_of_codes(np.array([-len(names) - 1]), names)
