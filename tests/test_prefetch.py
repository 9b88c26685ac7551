"""Reading ahead (:mod:`tollcli.io.prefetch`): the items in order, an error where the iterator raised it, the thread
stopped when the caller leaves (also by an error of its own), at most ``depth`` items waiting — and ``process``
writes the same invoice and epoch table with it and without it."""

from __future__ import annotations

import json
import os
import threading
import time

import pytest
from conftest import REPO, SAMPLES

from tollcli.charging.invoice import invoice_json
from tollcli.errors import DataError
from tollcli.io.prefetch import ENVIRONMENT, THREAD_NAME, read_ahead
from tollcli.job import pipeline
from tollcli.job.pipeline import ChargeSettings, charge_log

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")


_BEFORE: set = set()


@pytest.fixture(autouse=True)
def _threads_before(monkeypatch):
    """Reading ahead on (the suite may run with it off: conftest.py), and the reading threads alive before each test
    (another test's generator not yet collected): not this one's."""
    monkeypatch.setenv(ENVIRONMENT, "1")
    _BEFORE.clear()
    _BEFORE.update(t for t in threading.enumerate() if t.name == THREAD_NAME)


def _reader_threads() -> list[threading.Thread]:
    """This test's reading threads still alive."""
    return [t for t in threading.enumerate() if t.name == THREAD_NAME and t not in _BEFORE]


def _read(items, depth=1) -> list:
    with read_ahead(items, depth) as read:
        return list(read)


def test_items_come_in_order_each_once():
    assert _read(iter(range(1000)), depth=3) == list(range(1000))
    assert _read(iter([])) == []
    assert not _reader_threads()


def test_an_error_comes_after_every_item_before_it():
    def items():
        yield from range(5)
        raise DataError("log.nmea:12: bad")

    got = []
    with pytest.raises(DataError, match="log.nmea:12: bad"), read_ahead(items()) as read:
        for item in read:
            got.append(item)
    assert got == [0, 1, 2, 3, 4]
    assert not _reader_threads()


def test_leaving_early_stops_the_thread_and_closes_the_iterator():
    closed = []

    def items():
        try:
            for i in range(10**9):
                yield i
        finally:
            closed.append(True)

    with read_ahead(items()) as read:
        for item in read:
            if item == 3:
                break
    assert closed == [True]
    assert not _reader_threads()


def test_an_error_of_the_callers_stops_the_thread_though_its_traceback_lives_on():
    """The caller fails on an item and its error (with the frames that hold the reader) is kept: the thread is
    stopped anyway, when the ``with`` block is left, not when the error is forgotten."""
    with pytest.raises(ZeroDivisionError) as kept:
        with read_ahead(iter(range(10**9))) as read:
            for item in read:
                if item == 5:
                    1 / 0
    assert kept.value is not None and not _reader_threads()


def test_at_most_depth_items_wait_beyond_the_callers():
    made = []

    def items():
        for i in range(50):
            made.append(i)
            yield i

    with read_ahead(items(), depth=2) as it:
        assert next(it) == 0
        time.sleep(0.3)  # the thread has all the time it needs to run ahead
        assert len(made) <= 1 + 2  # the caller's and two waiting: the next is made only once there is room
        assert list(it) == list(range(1, 50))


def test_off_gives_the_iterator_itself(monkeypatch):
    monkeypatch.setenv(ENVIRONMENT, "0")
    items = iter(range(3))
    with read_ahead(items) as read:
        assert read is items
    assert not _reader_threads()


@pytest.mark.parametrize("log", ["sim/urban-fault/drive.nmea", "sim/rural-clean/drive.nmea", "straight-drive.nmea"])
def test_process_writes_the_same_invoice_reading_ahead_or_not(monkeypatch, log):
    """Chunks of 37 epochs, read ahead on a second thread or not: the same invoice bytes and epoch table."""
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 37)
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 2048)
    out = {}
    for ahead in ("1", "0"):
        monkeypatch.setenv(ENVIRONMENT, ahead)
        table: list = []
        invoice, _ = charge_log(str(SAMPLES / log), GEO, TARIFF, ChargeSettings(), roads=ROADS, epoch_table=table)
        out[ahead] = (invoice_json(invoice), table[0])
    assert out["1"][0] == out["0"][0]
    assert out["1"][1].equals(out["0"][1])
    assert len(out["1"][1]) > 37 * 4
    assert json.loads(out["1"][0])["lines"], "a drive that is charged"
    assert not _reader_threads()


def test_a_bad_line_in_strict_mode_is_the_same_error_reading_ahead(tmp_path, monkeypatch):
    """--strict on a log with a damaged line late in it: the same one-line error with and without reading ahead."""
    lines = (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()  # no bad line of its own
    lines[len(lines) * 3 // 4] = lines[len(lines) * 3 // 4][:-2] + "00"  # a wrong checksum
    log = tmp_path / "bad.nmea"
    log.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 37)
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 2048)
    errors = []
    for ahead in ("1", "0"):
        monkeypatch.setenv(ENVIRONMENT, ahead)
        with pytest.raises(DataError) as exc:
            charge_log(str(log), GEO, TARIFF, ChargeSettings(strict=True))
        errors.append(str(exc.value))
    assert errors[0] == errors[1]
    assert f"bad.nmea:{len(lines) * 3 // 4 + 1}:" in errors[0] and "checksum" in errors[0]
    assert not _reader_threads()


def test_batch_workers_on_every_core_do_not_read_ahead_unless_told(monkeypatch):
    """A pool whose workers take every core: each reads its logs on one thread (a second would only cost CPU), unless
    TOLLCLI_READ_AHEAD says otherwise; fewer workers than cores read ahead."""
    import os

    from tollcli.io import prefetch
    from tollcli.job import batch

    monkeypatch.setattr(batch, "die_with_parent", lambda pid: None)
    monkeypatch.setenv(ENVIRONMENT, "1")  # recorded as it was, restored after the test (the worker sets it directly)
    monkeypatch.delenv(ENVIRONMENT)
    batch._start_worker(1, one_thread=False)
    assert prefetch.read_ahead_on()
    batch._start_worker(1, one_thread=True)
    assert os.environ[ENVIRONMENT] == "0" and not prefetch.read_ahead_on()
    monkeypatch.setenv(ENVIRONMENT, "1")
    batch._start_worker(1, one_thread=True)
    assert prefetch.read_ahead_on()


@pytest.mark.parametrize("log", ["sim/urban-fault/drive.nmea", "straight-drive.nmea"])
def test_integrity_tables_are_the_same_reading_ahead_or_not(monkeypatch, log):
    """``integrity``, ``locate`` and ``findings`` read through ``iter_integrity``: the same tables on both paths."""
    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import iter_integrity

    tables = {}
    for ahead in ("1", "0"):
        monkeypatch.setenv(ENVIRONMENT, ahead)
        chunks = list(iter_integrity(str(SAMPLES / log), "nmea", RaimParams(hal_m=50.0)))
        tables[ahead] = [(c.table, c.satellites) for c in chunks]
    assert len(tables["1"]) == len(tables["0"]) >= 1
    for (a, sa), (b, sb) in zip(tables["1"], tables["0"]):
        assert a.equals(b) and sa.equals(sb)
    assert not _reader_threads()


def test_reading_ahead_is_the_default_outside_the_suite():
    """Reading ahead is the default outside the suite's full-machine runs (conftest.py turns it off there only)."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != ENVIRONMENT}
    code = "from tollcli.io.prefetch import read_ahead_on; print(read_ahead_on())"
    assert subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True).stdout.strip() == "True"
