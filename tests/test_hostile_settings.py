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
    """``date = 2024-05-06`` unquoted (a TOML date, as TOML users write it) was a TypeError (exit 5). (The log's own
    date: a --date that contradicts it is an error.)"""
    native, quoted = tmp_path / "native.toml", tmp_path / "quoted.toml"
    native.write_text("date = 2024-05-06\n")
    quoted.write_text('date = "2024-05-06"\n')
    invoices = []
    for settings in (native, quoted):
        out = tmp_path / f"{settings.stem}.json"
        done = run_cli("process", LOG, "--config", str(settings), "--geo", GEO, "--tariff", str(TARIFF), "-q", "-o", str(out))
        assert done.returncode == 0, done.stderr.decode()
        invoices.append(json.loads(out.read_text()))
    assert invoices[0]["parameters"]["date"] == invoices[1]["parameters"]["date"] == "2024-05-06"
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


@pytest.mark.parametrize("fee,says", [('"0.95"', "without quotes"), ("1e-320", "below the currency's minor unit"),
                                      ("0.004", "below the currency's minor unit")])  # fmt: skip
def test_a_fee_that_is_text_or_below_a_cent_is_refused(tmp_path, fee, says):
    """A fee written as text was taken as the number it spells; a fee of 1e-320 EUR charged 0.00 without a word."""
    tariff = tmp_path / "tariff.toml"
    tariff.write_text(TARIFF.read_text().replace("car = 0.95", f"car = {fee}", 1))
    out = tmp_path / "i.json"
    done = run_cli("process", LOG, "--geo", GEO, "--tariff", str(tariff), "-q", "-o", str(out))
    err = done.stderr.decode()
    assert done.returncode == 1 and says in err and "motorway" in err and not out.exists(), err
    assert len(err.strip().splitlines()) == 1


def test_a_free_passage_stays_possible(tmp_path):
    """0 is a fee (a free road class): the check is for amounts the rounding would turn into 0, not for 0 itself."""
    tariff = tmp_path / "tariff.toml"
    tariff.write_text(TARIFF.read_text().replace("car = 0.95", "car = 0", 1))
    out = tmp_path / "i.json"
    done = run_cli("process", LOG, "--geo", GEO, "--tariff", str(tariff), "-q", "-o", str(out))
    assert done.returncode == 0, done.stderr.decode()


@pytest.mark.parametrize("option", [("--p-sat", "1e-320"), ("--p-const", "0"), ("--p-md", "0.9"), ("--p-fa", "1")])
def test_a_probability_outside_its_range_is_refused(tmp_path, option):
    """``--p-sat 1e-320`` was taken as given (1 − p is 1 in floating point)."""
    done = run_cli("integrity", LOG, "-q", "-o", str(tmp_path / "i.csv"), *option)
    assert done.returncode == 2 and option[0] in done.stderr.decode() and not (tmp_path / "i.csv").exists()
