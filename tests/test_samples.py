"""The bundled samples are what their script makes, and they read as documented."""

import runpy

from conftest import SAMPLES
from tollcli.nmea import read_nmea


def test_sample_is_reproducible(tmp_path, monkeypatch):
    committed = (SAMPLES / "straight-drive.nmea").read_bytes()
    module = runpy.run_path(str(SAMPLES / "make_samples.py"), run_name="not_main")
    monkeypatch.setitem(module["main"].__globals__, "HERE", tmp_path)
    module["main"]()
    assert (tmp_path / "straight-drive.nmea").read_bytes() == committed


def test_sample_reads_as_documented():
    tables = read_nmea(SAMPLES / "straight-drive.nmea")
    s = tables.stats
    assert (s.lines, s.sentences, s.epochs, s.satellite_rows, s.bad_checksum, s.skipped) == (1622, 1619, 180, 1980, 1, 1)
    assert "line 103: bad checksum" in s.first_problem
