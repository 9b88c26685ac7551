"""The CLI as users meet it in shells: closed pipes, broken compressed files — documented exit codes, one line, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def test_a_reader_that_stops_early_is_not_an_error(tmp_path):
    """`tollcli epochs LOG | head`: exit 0 and nothing on stderr once head has what it wants."""
    log = tmp_path / "long.nmea"
    log.write_bytes(b"".join((SAMPLES / "sim" / d / "drive.nmea").read_bytes() for d in ("rural-clean", "urban-clean") * 4))
    proc = subprocess.Popen([sys.executable, "-m", "tollcli", "epochs", str(log), "-q"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ, NO_COLOR="1"))  # fmt: skip
    assert proc.stdout.read(100)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert err == ""


@pytest.mark.parametrize("content", [b"\x1f\x8b", b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03"], ids=["magic", "header"])
@pytest.mark.parametrize("command", ["process", "findings", "integrity", "epochs", "locate"])
def test_a_gzip_that_is_only_a_header_is_a_data_error(tmp_path, content, command):
    log = tmp_path / "day.nmea.gz"
    log.write_bytes(content)
    extra = {"process": ["--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "i.json")], "findings": ["--geo", GEO]}
    result = run_cli(command, str(log), *extra.get(command, []))
    err = result.stderr.decode()
    assert result.returncode == 1, err
    assert "interrupted" not in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "day.nmea.gz" in err
