"""Settings a user or an attacker may give (part of issue 54): absurd numbers are refused by the parser with the
option's range, a TOML native date is the date it means, and a byte-order mark opens a tariff or settings file."""

from __future__ import annotations

import json

import pytest
from conftest import REPO, SAMPLES, run_cli

LOG = str(SAMPLES / "straight-drive.nmea")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = REPO / "geoobjects" / "example-tariff.toml"


@pytest.mark.parametrize("option", [("--tc", "1e308"), ("--n-th", "10000000000"), ("--sigma", "1e-300"), ("--sigma", "0")])
def test_absurd_numbers_are_refused_with_the_range(tmp_path, option):
    """--tc 1e308 overflowed the thinning key (every fix independent, 0.95 EUR charged); the others were taken as given."""
    done = run_cli("process", LOG, "--geo", GEO, "--tariff", str(TARIFF), "-q", "-o", str(tmp_path / "i.json"), *option)
    assert done.returncode == 2 and option[0] in done.stderr.decode() and not (tmp_path / "i.json").exists()
    assert len(done.stderr.decode().strip().splitlines()) == 1


def test_an_infinite_hal_is_refused(tmp_path):
    done = run_cli("integrity", LOG, "--hal", "inf", "-q", "-o", str(tmp_path / "i.csv"))
    assert done.returncode == 2 and "--hal" in done.stderr.decode()


def test_a_toml_date_is_the_date_it_means(tmp_path):
    """``date = 2026-03-02`` unquoted (a TOML date, as TOML users write it) was a TypeError (exit 5)."""
    native, quoted = tmp_path / "native.toml", tmp_path / "quoted.toml"
    native.write_text("date = 2026-03-02\n")
    quoted.write_text('date = "2026-03-02"\n')
    invoices = []
    for settings in (native, quoted):
        out = tmp_path / f"{settings.stem}.json"
        done = run_cli("process", LOG, "--config", str(settings), "--geo", GEO, "--tariff", str(TARIFF), "-q", "-o", str(out))
        assert done.returncode == 0, done.stderr.decode()
        invoices.append(json.loads(out.read_text()))
    assert invoices[0]["parameters"]["date"] == invoices[1]["parameters"]["date"] == "2026-03-02"
    assert invoices[0]["lines"] == invoices[1]["lines"]


def test_a_byte_order_mark_opens_a_tariff(tmp_path):
    """A tariff saved with a UTF-8 byte-order mark was "not a TOML tariff (Invalid statement …)": the same charges."""
    with_bom = tmp_path / "tariff.toml"
    with_bom.write_bytes(b"\xef\xbb\xbf" + TARIFF.read_bytes())
    totals = []
    for tariff in (TARIFF, with_bom):
        out = tmp_path / "i.json"
        done = run_cli("process", LOG, "--geo", GEO, "--tariff", str(tariff), "-q", "-o", str(out))
        assert done.returncode == 0, done.stderr.decode()
        totals.append(json.loads(out.read_text())["total"])
    assert totals[0] == totals[1] != "0.00"
