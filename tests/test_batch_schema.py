"""The batch's epoch dataset is one table whatever the input kinds: every file has the same columns and types.

Before: NMEA, GSDC-derived and device_gnss logs wrote different columns (``alt_m`` vs ``height_m``…), and DuckDB
and pandas silently kept the first file's 62 of 70 columns."""

from __future__ import annotations

import shutil

import pyarrow.parquet as pq
import pytest
from conftest import REPO, SAMPLES, run_cli, shared

from tollcli.job.epoch_schema import EPOCH_COLUMNS, epoch_schema, unknown_columns

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mixed")
    logs = tmp / "logs"
    logs.mkdir()
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", logs / "nmea.nmea")
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive-derived.csv", logs / "derived.csv")
    shutil.copy(shared("gsdc2022", "device_gnss.csv"), logs / "phone.csv")
    r = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp / "out"), "-q")
    assert r.returncode == 0, r.stderr
    return tmp / "out"


def test_every_file_of_a_mixed_batch_has_the_one_schema(mixed):
    files = sorted((mixed / "epochs").rglob("*.parquet"))
    assert len(files) == 3
    for f in files:
        assert pq.read_schema(f).remove_metadata() == epoch_schema(), f


def test_duckdb_reads_the_mixed_batch_as_one_table(mixed):
    duckdb = pytest.importorskip("duckdb")
    con = duckdb.connect()
    query = f"FROM read_parquet('{mixed / 'epochs'}/*/*/*.parquet', hive_partitioning = true)"
    assert len(con.sql(f"SELECT * {query} LIMIT 1").columns) == len(EPOCH_COLUMNS) + 2  # + date, vehicle
    rows = dict(((v, (n, h, a, s)) for v, n, h, a, s in con.sql(
        f"SELECT vehicle, count(*), count(height_m), count(alt_m), count(speed_mps) {query} GROUP BY vehicle").fetchall()))  # fmt: skip
    assert rows["nmea"][0] == rows["nmea"][1] == rows["nmea"][2] == 230  # NMEA: ellipsoidal height from GGA + geoid
    assert rows["derived"][1] == 230 and rows["derived"][2] == 0 and rows["derived"][3] == 0  # no speed: null, not 0
    assert rows["phone"][1] > 0 and rows["phone"][3] > 0


def test_every_reader_s_columns_are_in_the_schema():
    """A reader that grows a column must grow the schema: each input kind's epoch table, checked."""
    from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
    from tollcli.gnss.sigma_models import NominalModel
    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import iter_integrity
    from tollcli.readers.nmea import ReadStats

    tables = [c.table for c in iter_integrity(str(SAMPLES / "sim" / "urban-fault" / "drive.nmea"), "nmea", RaimParams(),
                                                stats=ReadStats())]  # fmt: skip
    for log, kind in ((SAMPLES / "sim" / "rural-clean" / "drive-derived.csv", "gsdc-derived"),
                      (shared("gsdc2022", "device_gnss.csv"), "device-gnss")):  # fmt: skip
        tables.append(pseudorange_epochs(str(log), kind, None, "nominal", 5.0, NominalModel())[0])
    for table in tables:
        assert unknown_columns(table) == []
