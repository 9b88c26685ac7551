"""The bundled samples are what their script makes, and they read as documented."""

import json
import runpy

from conftest import SAMPLES

from tollcli.readers.nmea import read_nmea


def test_samples_are_reproducible(tmp_path, monkeypatch):
    module = runpy.run_path(str(SAMPLES / "make_samples.py"), run_name="not_main")
    monkeypatch.setitem(module["main"].__globals__, "HERE", tmp_path)
    monkeypatch.setitem(module["main"].__globals__, "GEO", tmp_path)
    module["main"]()
    assert (tmp_path / "straight-drive.nmea").read_bytes() == (SAMPLES / "straight-drive.nmea").read_bytes()
    geo = SAMPLES.parent / "geoobjects"
    for name in ("example-roads.geojson", "example-geoobjects.geojson"):
        assert (tmp_path / name).read_bytes() == (geo / name).read_bytes(), name
    for drive in module["DRIVES"]:
        for name in ("drive.nmea", "drive-derived.csv", "truth.csv", "truth-geoobjects.json"):
            assert (tmp_path / "sim" / drive / name).read_bytes() == (SAMPLES / "sim" / drive / name).read_bytes(), (drive, name)
        made = json.loads((SAMPLES / "sim" / drive / "manifest.json").read_text())
        assert made["command"].startswith("tollcli simulate --route geoobjects/example-roads.geojson")
        assert made["command"].endswith(f"-o samples/sim/{drive}")


def test_sample_reads_as_documented():
    tables = read_nmea(SAMPLES / "straight-drive.nmea")
    s = tables.stats
    assert (s.lines, s.sentences, s.epochs, s.satellite_rows, s.bad_checksum, s.skipped) == (1622, 1619, 180, 1980, 1, 1)
    assert "line 103: bad checksum" in s.first_problem
