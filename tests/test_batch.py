"""``tollcli batch``: many logs, resumable, a bad log reported, the same bytes on a process pool and on Dask."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import REPO, SAMPLES, run_cli

from tollcli.job.batch import run_batch
from tollcli.job.log_files import expand_inputs
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
    assert first.returncode == 6, first.stderr.decode()  # some failed: one log (exit 3 is --max-bad's)
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


# ---------------------------------------------------------------- outputs unique per input, resume only when current
def _invoices(out: Path) -> list[Path]:
    return sorted((out / "invoices").rglob("*.json"))


def test_logs_with_the_same_name_on_different_days_keep_their_own_invoices(tmp_path):
    """day1/TRK-042.nmea, day2/TRK-042.nmea, truck1.day1.nmea, truck1.day2.nmea: four logs, four invoices, stable on rerun."""
    src = SAMPLES / "sim"
    for day, sim in (("day1", "rural-clean"), ("day2", "urban-clean")):
        (tmp_path / day).mkdir()
        shutil.copy(src / sim / "drive.nmea", tmp_path / day / "TRK-042.nmea")
    shutil.copy(src / "urban-fault" / "drive.nmea", tmp_path / "truck1.day1.nmea")
    shutil.copy(src / "rural-fault" / "drive.nmea", tmp_path / "truck1.day2.nmea")
    logs = expand_inputs([str(tmp_path / "day1"), str(tmp_path / "day2"), str(tmp_path / "truck1.day1.nmea"),
                          str(tmp_path / "truck1.day2.nmea")])  # fmt: skip
    out = tmp_path / "out"
    first = run_batch(logs, GEO, TARIFF, ChargeSettings(), str(out))
    assert (first["done"], first["skipped"]) == (4, 0)
    invoices = _invoices(out)
    assert len(invoices) == 4 and len({json.loads(p.read_text())["inputs"]["log"] for p in invoices}) == 4
    assert len(list((out / "epochs").rglob("*.parquet"))) == 4
    again = run_batch(logs, GEO, TARIFF, ChargeSettings(), str(out))
    assert (again["done"], again["skipped"]) == (0, 4) and _invoices(out) == invoices
    # a later day's log of the same name added to the same OUTDIR: the earlier invoices stay as they are
    (tmp_path / "day3").mkdir()
    shutil.copy(src / "urban-fault" / "drive.nmea", tmp_path / "day3" / "TRK-042.nmea")
    later = run_batch([*logs, str(tmp_path / "day3" / "TRK-042.nmea")], GEO, TARIFF, ChargeSettings(), str(out))
    assert (later["done"], later["skipped"]) == (1, 4) and len(_invoices(out)) == 5


def test_resume_redoes_a_log_when_the_tariff_or_a_setting_changed(tmp_path):
    log = tmp_path / "TRK-1.nmea"
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", log)
    out = tmp_path / "out"
    assert run_batch([str(log)], GEO, TARIFF, ChargeSettings(), str(out))["done"] == 1
    dear = tmp_path / "dear.toml"
    dear.write_text(Path(TARIFF).read_text().replace("car = 0.95", "car = 9.50"))
    redo = run_batch([str(log)], GEO, str(dear), ChargeSettings(), str(out))
    assert redo["done"] == 1 and redo["totals"] == {"EUR": "23.76"}
    assert run_batch([str(log)], GEO, str(dear), ChargeSettings(), str(out))["skipped"] == 1
    assert run_batch([str(log)], GEO, str(dear), ChargeSettings(vehicle_class="truck"), str(out))["done"] == 1
    assert run_batch([str(log)], GEO, str(dear), ChargeSettings(vehicle_class="truck", n_th=2), str(out))["done"] == 1


@pytest.mark.parametrize("vehicle", ["../../escaped", "/abs/escaped", "..", ".hidden", "a/b\\c"])
def test_a_vehicle_id_from_a_log_never_writes_outside_outdir(tmp_path, vehicle):
    log = tmp_path / "logs" / "TRK-7.nmea"
    log.parent.mkdir()
    log.write_bytes(f"# vehicle: {vehicle}\n".encode() + (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_bytes())
    out = tmp_path / "deep" / "er" / "out"
    summary = run_batch([str(log)], GEO, TARIFF, ChargeSettings(), str(out))
    assert summary["done"] == 1 and summary["outcomes"][0]["vehicle"] == vehicle
    written = [p for p in tmp_path.rglob("*") if p.is_file() and "logs" not in p.parts]
    assert written and all(out in p.parents for p in written), written
    invoice = json.loads(next(out.glob("invoices/*/*.json")).read_text())
    assert invoice["vehicle"] == vehicle


def test_a_log_that_crashes_the_tool_is_reported_and_the_others_go_on(tmp_path, monkeypatch):
    from tollcli.job import batch

    good, bad = tmp_path / "good.nmea", tmp_path / "bad.nmea"
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", good)
    shutil.copy(SAMPLES / "sim" / "urban-clean" / "drive.nmea", bad)
    real = batch.charge_log

    def flaky(log, *args, **kwargs):
        if log.endswith("bad.nmea"):
            raise RuntimeError("boom")
        return real(log, *args, **kwargs)

    monkeypatch.setattr(batch, "charge_log", flaky)
    summary = run_batch([str(bad), str(good)], GEO, TARIFF, ChargeSettings(), str(tmp_path / "out"))
    assert (summary["done"], summary["failed"]) == (1, 1)
    assert "internal error (RuntimeError: boom)" in (tmp_path / "out" / "failed" / "bad.txt").read_text()


def _children(pid: int) -> set[int]:
    try:
        return {int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()}
    except OSError:
        return set()


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc to find the pool's workers")
@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_ending_the_batch_ends_its_pool_workers(tmp_path, how):
    """The batch parent killed (SIGKILL: no chance to clean up) or terminated: no pool worker outlives it,
    and nothing half-written is left in the output folder."""
    import os
    import signal
    import subprocess
    import sys
    import time

    folder = tmp_path / "logs"
    folder.mkdir()
    for i in range(16):
        shutil.copy(SAMPLES / "sim" / "urban-fault" / "drive.nmea", folder / f"TRK-{i:02d}.nmea")
    out = tmp_path / "out"
    parent = subprocess.Popen([sys.executable, "-m", "tollcli", "batch", str(folder), "--geo", GEO, "--tariff", TARIFF,
                               "--workers", "2", "-q", "-o", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              start_new_session=True)  # fmt: skip
    workers: set[int] = set()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and parent.poll() is None:
        workers = {p for p in _children(parent.pid) if _alive(p)}
        if len(workers) >= 2 and (out / "epochs").exists():
            break
        time.sleep(0.05)
    assert len(workers) >= 2 and parent.poll() is None, "the batch ended before its workers were seen"
    parent.send_signal(getattr(signal, how))
    rc = parent.wait(timeout=30)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.05)
    left = [p for p in workers if _alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"pool workers still running after the batch ended ({how})"
    assert rc == (-9 if how == "SIGKILL" else 143), parent.stderr.read().decode()
    if how == "SIGTERM":
        assert not [p.name for p in out.rglob("*") if p.name.endswith(".tmp") or ".tmp" in p.name]


def test_the_same_drive_twice_for_one_vehicle_is_charged_and_said(tmp_path):
    """One drive uploaded twice under two names: each log keeps its invoice, and the overlap is reported
    (outcomes name each other, the summary counts them, the CLI warns)."""
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("TRK-5.morning.nmea", "TRK-5.again.nmea"):
        shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", folder / name)
    shutil.copy(SAMPLES / "sim" / "urban-clean" / "drive.nmea", folder / "TRK-6.nmea")
    result = run_cli("batch", str(folder), "--geo", GEO, "--tariff", TARIFF, "--vehicle-class", "car", "--workers", "1",
                     "-o", str(tmp_path / "out"))  # fmt: skip
    assert result.returncode == 0, result.stderr.decode()
    assert "2 logs overlap in time another log of the same vehicle" in result.stderr.decode()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["overlapping"] == 2 and summary["done"] == 3
    named = {Path(o["log"]).name: [Path(x).name for x in o.get("overlaps", [])] for o in summary["outcomes"]}
    assert named == {"TRK-5.again.nmea": ["TRK-5.morning.nmea"], "TRK-5.morning.nmea": ["TRK-5.again.nmea"], "TRK-6.nmea": []}
