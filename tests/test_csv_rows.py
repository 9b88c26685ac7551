"""The CSV writer's compiled rows (tollcli/io/_csv_kernel.c, tollcli.io.csv_rows) against the csv module's: the same
bytes for every float Python can format, for tables of every kind of column, and for the epoch and satellite tables
of every real log in ../shared/data/gpsd; chunks the kernel cannot write exactly are left to the csv module."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SAMPLES, shared
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tollcli.io import csv_rows
from tollcli.io.columns import Coded, Columns
from tollcli.io.writers import TableWriter

needs_compiled = pytest.mark.skipif(csv_rows.compiled is None, reason="compiled CSV kernel not built")


def test_the_install_built_the_csv_kernel():
    """`pip install .` compiles it (a C compiler and Python's headers are on this machine and in CI)."""
    assert csv_rows.compiled is not None, "compiled CSV kernel not built (see README: pip install needs a C compiler)"


def _reference(v: float) -> str:
    return "" if math.isnan(v) else "%.15g" % v


#: values at the kernel's edges: its range without an exponent, ties at the 15th digit, powers of ten, rounding up
#: to the next power, the smallest and largest doubles
EDGES = [0.0, -0.0, math.inf, -math.inf, math.nan, 1e-4, 9.99999999999999e-5, 1e-5, 1e15, 1e15 - 0.125, 999999999999999.9,
         99999999999999.95, 123456789012345.5, 123456789012344.5, 0.5, 2.5, 0.1, 0.3, 1 / 3, 2 / 3, 5e-324, 1.7976931348623157e308,
         2.2250738585072014e-308, 0.00012345678901234567, 42.698859, -2.8956, 24.9999422222222, 4503599627370495.5,
         9007199254740993.0, 1e-4 * (1 + 2**-52), 0.000999999999999999999, 9.999999999999999, 99.99999999999999]  # fmt: skip


@needs_compiled
@settings(max_examples=3000, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True, width=64))
@example(123456789012345.5)
def test_a_float_cell_is_pythons_percent_15g(v):
    assert csv_rows.compiled.float_cell(v) == _reference(v)


@needs_compiled
def test_float_cells_at_the_edges_and_in_bulk_are_pythons_percent_15g():
    rng = np.random.default_rng(2026)
    edges = np.array(EDGES)
    with np.errstate(over="ignore"):
        near = [np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)]
    scale = 10.0 ** rng.integers(0, 12, 100_000)
    values = np.concatenate([
        edges, *near,
        rng.integers(0, 2**64, 100_000, dtype=np.uint64).view(np.float64),  # every exponent, every mantissa
        np.round(rng.uniform(-180, 180, 100_000) * scale) / scale,  # what receivers write: a few decimals
        10 ** rng.uniform(-6, 17, 100_000) * rng.choice([-1, 1], 100_000),
        np.arange(10**14, 10**14 + 2000) + 0.5,  # exact ties at the 15th digit
    ])  # fmt: skip
    text = csv_rows.compiled.rows(b"fi", (values, np.arange(values.size, dtype=np.int64)), values.size).decode()
    want = "".join(f"{_reference(v)},{i}\n" for i, v in enumerate(values.tolist()))
    assert text == want


def _written(table, tmp_path, name: str, compiled, second=None) -> bytes:
    """``table`` (numpy columns or a DataFrame) then ``second`` (default: ``table`` again: a second chunk, no header
    again) written as CSV through TableWriter, with the kernel ``compiled`` (None: the reference)."""
    saved = csv_rows.compiled
    csv_rows.compiled = compiled
    try:
        path = tmp_path / name
        with TableWriter(str(path), "csv") as writer:
            writer.write(table)
            writer.write(table if second is None else second)
            writer.commit()
        return path.read_bytes()
    finally:
        csv_rows.compiled = saved


@needs_compiled
def test_a_table_of_every_kind_of_column_is_the_csv_modules(tmp_path):
    rng = np.random.default_rng(7)
    n = 2000
    times = np.datetime64("2024-05-06T00:00:00", "ms") + rng.integers(0, 10**9, n).astype("timedelta64[ms]")
    times[::17] = np.datetime64("NaT")
    floats = rng.normal(0, 1e3, n)
    floats[::5] = np.nan
    text = np.array([["A", "", None, "dé", "x y"][i % 5] for i in range(n)], dtype=object)
    table = Columns({"time_utc": times, "lat_deg": floats, "f32": floats.astype(np.float32), "n": rng.integers(-10**12, 10**12, n),
                     "u8": rng.integers(0, 255, n).astype(np.uint8), "ok": rng.random(n) < 0.5, "mode": text,
                     "constellation": Coded(rng.integers(0, 3, n), ("GPS", "Galileo", "BeiDou"))})  # fmt: skip
    assert csv_rows.csv_text(table, lambda v: [""] * len(v)) is not None  # the kernel writes this one
    assert _written(table, tmp_path, "fast.csv", csv_rows.compiled) == _written(table, tmp_path, "ref.csv", None)


@needs_compiled
@pytest.mark.parametrize("cell", ["a,b", 'say "x"', "two\nlines", "cr\r"])
def test_a_text_cell_the_csv_module_would_quote_leaves_the_chunk_to_it(tmp_path, cell):
    for note in (np.array(["plain", cell, None], dtype=object), Coded(np.array([0, 1, 0]), ("plain", cell))):
        table = Columns({"id": np.arange(3), "note": note})
        assert csv_rows.csv_text(table, None) is None
        fast, ref = _written(table, tmp_path, "fast.csv", csv_rows.compiled), _written(table, tmp_path, "ref.csv", None)
        assert fast == ref and cell.replace('"', '""') in fast.decode()


@needs_compiled
def test_the_kernel_refuses_offsets_outside_its_cells():
    with pytest.raises(ValueError, match="offsets"):
        csv_rows.compiled.rows(b"c", ((b"abc", np.array([0, 2, 9], np.int64)),), 2)
    with pytest.raises(ValueError, match="offsets"):
        csv_rows.compiled.rows(b"c", ((b"abc", np.array([0, 2, 1], np.int64)),), 2)
    with pytest.raises(ValueError, match="too short"):
        csv_rows.compiled.rows(b"f", (np.zeros(2),), 3)
    with pytest.raises(ValueError, match="kind"):
        csv_rows.compiled.rows(b"z", (np.zeros(2),), 2)


@needs_compiled
def test_every_real_logs_epoch_and_satellite_tables_are_the_csv_modules(tmp_path):
    """What `tollcli epochs` writes: each gpsd log's tables (chunks of :class:`Columns`) through the kernel and through
    the csv module, the same bytes."""
    from tollcli.io.log_run import LogRun
    from tollcli.readers.navigation import NAVIGATION_KINDS, iter_epoch_tables

    logs = sorted(p for p in shared("gpsd").iterdir() if not p.name.endswith(".chk") and p.is_file() and "COPYING" not in p.name)
    logs.append(SAMPLES / "sim" / "urban-fault" / "drive.nmea")
    written, cells = 0, 0
    for log in logs:
        try:
            with LogRun(str(log), "auto", hashed=False) as run:
                if run.kind not in NAVIGATION_KINDS:
                    continue
                chunks = list(iter_epoch_tables(run, strict=False))
        except Exception:  # noqa: BLE001 - a log no reader takes: nothing written from it
            continue
        for chunk in chunks:
            for table in (chunk.epoch_columns, chunk.satellite_columns):
                if not len(table):
                    continue
                fast = _written(table, tmp_path, "fast.csv", csv_rows.compiled)
                assert fast == _written(table, tmp_path, "ref.csv", None), log.name
                written += 1
                cells += len(table) * len(table.columns)
    assert written > 200 and cells > 500_000  # the comparison covered the real logs' tables (256 tables, 631 003 cells)


# ---- DataFrames: what pandas' to_csv writes (integrity, locate, findings tables) ------------------------------------

def _frame_written(df, tmp_path, name: str, compiled) -> bytes:
    return _written(df, tmp_path, name, compiled, second=df.iloc[:3])


def _mixed_frame(n: int = 1500):
    import pandas as pd

    rng = np.random.default_rng(11)
    floats = rng.normal(0, 1e4, n)
    floats[::7], floats[1::97], floats[2::89] = np.nan, np.inf, -0.0
    times = pd.Series(pd.to_datetime(rng.integers(1.7e12, 1.8e12, n), unit="ms", utc=True))
    times[::13] = pd.NaT
    status = pd.array([["valid", "fault_detected", None, "unavailable"][i % 4] for i in range(n)], dtype="string")
    return pd.DataFrame({"time_utc": times, "hpl_m": floats, "n_used": rng.integers(0, 30, n).astype(np.int16),
                         "fix_mode": rng.integers(-3, 3, n).astype(np.int8), "line": rng.integers(0, 10**12, n),
                         "valid": rng.random(n) < 0.5, "raim_status": status,
                         "note": np.array([["a b", None, float("nan"), "dé"][i % 4] for i in range(n)], dtype=object)})  # fmt: skip


@needs_compiled
def test_a_frame_of_every_kind_the_kernel_writes_is_pandas_to_csv(tmp_path):
    df = _mixed_frame()
    assert csv_rows.frame_csv_text(df.assign(time_utc=df["time_utc"].astype(str))) is not None  # the kernel writes it
    assert _frame_written(df, tmp_path, "fast.csv", csv_rows.compiled) == _frame_written(df, tmp_path, "ref.csv", None)


@needs_compiled
@pytest.mark.parametrize("change", ["nullable_int", "category", "numbers_as_objects", "quoted_text", "naive_time", "float32"])
def test_a_frame_column_the_kernel_does_not_write_leaves_the_chunk_to_pandas(tmp_path, change):
    import pandas as pd

    df = _mixed_frame(300)
    col = {"nullable_int": pd.array([1, None, 3] * 100, dtype="Int64"), "category": pd.Categorical(["a", "b", "c"] * 100),
           "numbers_as_objects": np.array([1, 2.5, None] * 100, dtype=object), "quoted_text": np.array(["x,y", "z", None] * 100, dtype=object),
           "naive_time": pd.to_datetime(np.arange(300), unit="s"), "float32": np.linspace(0, 1, 300, dtype=np.float32)}[change]  # fmt: skip
    df = df.assign(extra=col)
    assert csv_rows.frame_csv_text(df) is None
    assert _frame_written(df, tmp_path, "fast.csv", csv_rows.compiled) == _frame_written(df, tmp_path, "ref.csv", None)


@needs_compiled
def test_every_real_logs_integrity_table_is_pandas_to_csv(tmp_path):
    """What `tollcli integrity` writes: each gpsd NMEA log's integrity chunks through the kernel and through pandas, the
    same bytes; and the kernel wrote them (no chunk left to pandas)."""
    import pandas as pd

    from tollcli.integrity.raim import RaimParams
    from tollcli.io.writers import iso_utc
    from tollcli.job.log_integrity import iter_integrity

    logs = sorted(p for p in shared("gpsd").iterdir() if p.suffix == ".log" and p.is_file())
    logs.append(SAMPLES / "sim" / "urban-fault" / "drive.nmea")
    written = rows = left_to_pandas = 0
    for log in logs:
        try:
            chunks = [c.table for c in iter_integrity(str(log), "nmea", RaimParams())]
        except Exception:  # noqa: BLE001 - not an NMEA log (binary): the epochs test covers what reads it
            continue
        for table in chunks:
            if table.empty:
                continue
            fast = _frame_written(table, tmp_path, "fast.csv", csv_rows.compiled)
            assert fast == _frame_written(table, tmp_path, "ref.csv", None), log.name
            as_written = table.assign(**{c: iso_utc(table[c]) for c in table.columns if isinstance(table[c].dtype, pd.DatetimeTZDtype)})
            left_to_pandas += csv_rows.frame_csv_text(as_written) is None
            written += 1
            rows += len(table)
    assert written > 90 and rows > 2_000  # the real logs' tables were compared (98 tables, 2 433 rows)
    assert left_to_pandas == 0
