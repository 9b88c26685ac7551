"""``tollcli batch``: many logs, resumable, a bad log reported, the same bytes on a process pool and on Dask."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import REPO, SAMPLES, run_cli

from tollcli.job.batch import expand_inputs, run_batch
from tollcli.job.pipeline import ChargeSettings

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("logs")
    for name in ("rural-clean", "urban-clean", "urban-fault", "rural-fault"):
        shutil.copy(SAMPLES / "sim" / name / "drive.nmea", folder / f"TRK-{name}.nmea")
    (folder / "broken.nmea").write_text("this is not a receiver log\n")
    return folder


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_pool_sizes_and_dask_give_the_same_bytes(logs, tmp_path):
    from distributed import LocalCluster

    found = expand_inputs([str(logs)])
    outs = {}
    for label, kwargs in (("one", {"workers": 1}), ("two", {"workers": 2})):
        outs[label] = tmp_path / label
        run_batch(found, GEO, TARIFF, ChargeSettings(), str(outs[label]), **kwargs)
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        outs["dask"] = tmp_path / "dask"
        summary = run_batch(found, GEO, TARIFF, ChargeSettings(), str(outs["dask"]), scheduler=cluster.scheduler_address)
    assert (summary["done"], summary["failed"]) == (4, 1)
    reference = _files(outs["one"])
    assert len(reference) == 10  # 4 invoices, 4 epoch tables, 1 failure note, the summary
    for label in ("two", "dask"):
        assert _files(outs[label]) == reference, label


def test_cli_resumes_reports_the_bad_log_and_writes_a_dataset(logs, tmp_path):
    import pyarrow.dataset as ds

    out = tmp_path / "out"
    (tmp_path / "list.txt").write_text("\n".join(str(p) for p in sorted(logs.glob("*.nmea"))) + "\n")
    first = run_cli("batch", f"@{tmp_path / 'list.txt'}", "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "--workers", "2", "--json")
    assert first.returncode == 3, first.stderr.decode()  # partial: one log failed
    summary = json.loads(first.stdout)
    assert (summary["logs"], summary["done"], summary["failed"], summary["totals"]) == (5, 4, 1, {"EUR": "9.52"})
    assert "broken.nmea" in first.stderr.decode() and (out / "failed" / "broken.txt").exists()
    again = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "--json")
    assert json.loads(again.stdout)["skipped"] == 4  # resumed: nothing redone
    forced = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "--force", "--json")
    assert json.loads(forced.stdout)["done"] == 4
    table = ds.dataset(str(out / "epochs"), format="parquet", partitioning="hive").to_table()
    assert table.num_rows == 4 * 230
    assert sorted(set(table.column("vehicle").to_pylist())) == ["TRK-rural-clean", "TRK-rural-fault", "TRK-urban-clean", "TRK-urban-fault"]
    assert set(table.column("date").to_pylist()) == {"2026-03-02"} and "raim_status" in table.column_names
    # the dataset as DuckDB sees it: one table, date and vehicle from the folder names
    import duckdb

    rows = duckdb.sql(
        f"SELECT vehicle, count(*) AS epochs, sum(CASE WHEN raim_status = 'valid' THEN 1 ELSE 0 END) AS valid "
        f"FROM read_parquet('{out / 'epochs'}/*/*/*.parquet', hive_partitioning = true) GROUP BY vehicle ORDER BY vehicle"
    ).fetchall()  # fmt: skip
    assert [r[0] for r in rows] == ["TRK-rural-clean", "TRK-rural-fault", "TRK-urban-clean", "TRK-urban-fault"]
    assert all(r[1] == 230 for r in rows) and all(0 < r[2] <= 230 for r in rows)
    # a log that changed is processed again
    invoice = json.loads((out / "invoices" / "TRK-rural-clean" / "TRK-rural-clean.json").read_text())
    assert invoice["vehicle"] == "TRK-rural-clean" and invoice["total"] == "2.38"


def test_every_log_bad_is_a_data_error(tmp_path):
    (tmp_path / "a.nmea").write_text("nothing\n")
    result = run_cli("batch", str(tmp_path / "a.nmea"), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "o"))
    assert result.returncode == 1
    assert run_cli("batch", str(tmp_path / "nothing-*.nmea"), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "o")).returncode == 2
