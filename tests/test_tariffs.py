"""Tariffs: Decimal money, geo-object and road-class fees, time bands, and bad files."""

from __future__ import annotations

import datetime as dt
from decimal import Decimal
from pathlib import Path

import pytest

from tollcli.charging.tariffs import load_tariff
from tollcli.errors import DataError

EXAMPLE = Path(__file__).resolve().parents[1] / "geoobjects" / "example-tariff.toml"
UTC = dt.timezone.utc


def _tariff(tmp_path, text: str):
    path = tmp_path / "t.toml"
    path.write_text(text)
    return load_tariff(str(path))


def test_example_tariff_bands_in_local_time():
    t = load_tariff(str(EXAMPLE))
    # Monday 2024-05-06, Paris is UTC+2 in May: 06:00 UTC = 08:00 local, in the morning peak
    assert t.fee("A9-1", "motorway", "car", dt.datetime(2024, 5, 6, 6, 0, tzinfo=UTC)) == (Decimal("1.19"), "morning-peak")
    # 0.95 × 1.25 = 1.1875 → 1.19 (half-up to cents); 12:00 local: no band
    assert t.fee("A9-1", "motorway", "car", dt.datetime(2024, 5, 6, 10, 0, tzinfo=UTC)) == (Decimal("0.95"), "")
    # Saturday 08:00 local: the peak is weekdays only
    assert t.fee("A9-1", "motorway", "truck", dt.datetime(2024, 5, 11, 6, 0, tzinfo=UTC)) == (Decimal("3.15"), "")
    # the night band wraps past midnight: 23:30 and 05:59 local are in it, 06:00 is not
    assert t.fee("x", "expressway", "van", dt.datetime(2024, 5, 6, 21, 30, tzinfo=UTC))[1] == "night"
    assert t.fee("x", "expressway", "van", dt.datetime(2024, 5, 7, 3, 59, tzinfo=UTC)) == (Decimal("0.64"), "night")
    assert t.fee("x", "expressway", "van", dt.datetime(2024, 5, 7, 4, 0, tzinfo=UTC))[1] == ""
    # winter time: 06:00 UTC = 07:00 local in January, the peak starts
    assert t.fee("x", "motorway", "car", dt.datetime(2024, 1, 8, 6, 0, tzinfo=UTC))[1] == "morning-peak"


def test_money_is_exact_decimal_and_geoobject_fee_wins(tmp_path):
    t = _tariff(tmp_path, 'currency = "EUR"\n[road_class.motorway]\ncar = 0.1\n[geoobject."A9-1"]\ncar = 0.2\n')
    total = sum(t.fee(g, "motorway", "car", dt.datetime(2024, 1, 1, tzinfo=UTC))[0] for g in ("x", "A9-1"))
    assert total == Decimal("0.30")  # 0.1 + 0.2, exactly: never a binary float
    assert isinstance(t.road_class["motorway"]["car"], Decimal)


@pytest.mark.parametrize(
    "text, message",
    [
        ('[road_class.m]\ncar = 1\n', "currency"),
        ('currency = "EUR"\n', "no fees"),
        ('currency = "EUR"\n[road_class.m]\ncar = -1\n', "≥ 0"),
        ('currency = "EUR"\n[road_class.m]\ncar = "abc"\n', "not a number"),
        ('currency = "EUR"\ntimezone = "Mars/Olympus"\n[road_class.m]\ncar = 1\n', "timezone"),
        ('currency = "EUR"\n[road_class.m]\ncar = 1\n[[band]]\nstart = "25:00"\nend = "26:00"\nfactor = 1\n', "HH:MM"),
        ('currency = "EUR"\n[road_class.m]\ncar = 1\n[[band]]\nname = "a"\nstart = "07:00"\nend = "09:00"\nfactor = 2\n'
         '[[band]]\nname = "b"\nstart = "08:00"\nend = "10:00"\nfactor = 3\n', "overlap"),
        ('currency = "EUR"\n[road_class.m]\ncar = 1\n[[band]]\nstart = "07:00"\nfactor = 2\n', "missing end"),
        ('currency = EUR\n', "not a TOML"),
    ],
)
def test_bad_tariffs_are_clear_data_errors(tmp_path, text, message):
    with pytest.raises(DataError, match=message):
        _tariff(tmp_path, text)


def test_missing_fee_names_what_is_missing(tmp_path):
    t = load_tariff(str(EXAMPLE))
    with pytest.raises(DataError, match="vehicle class 'bus'"):
        t.fee("A9-1", "motorway", "bus", dt.datetime(2024, 5, 6, tzinfo=UTC))
    with pytest.raises(DataError, match="road class 'cycleway'"):
        t.fee("A9-1", "cycleway", "car", dt.datetime(2024, 5, 6, tzinfo=UTC))


# ---------------------------------------------------------------- typos never change a fee silently
MINIMAL = 'currency = "EUR"\nminor_unit = 2\n\n[road_class.motorway]\ncar = 1.20\n'


@pytest.mark.parametrize("text, line, key", [
    ('currency = "EUR"\ntimezon = "Europe/Paris"\n[road_class.motorway]\ncar = 1\n', 2, "timezon"),
    ('curency = "EUR"\n[road_class.motorway]\ncar = 1\n', 1, "curency"),
    (MINIMAL + '\n[[band]]\nname = "peak"\nstart = "07:00"\nend = "09:00"\nfactr = 1.5\n', 11, "factr"),
    (MINIMAL + '[roadclass.trunk]\ncar = 1\n', 6, "roadclass"),
])  # fmt: skip
def test_an_unknown_key_is_an_error_naming_it_and_its_line(tmp_path, text, line, key):
    with pytest.raises(DataError) as err:
        _tariff(tmp_path, text)
    message = str(err.value)
    assert f"t.toml:{line}:" in message and repr(key) in message and "\n" not in message


def test_a_misspelt_day_is_an_error(tmp_path):
    with pytest.raises(DataError, match=r"t.toml:10: band peak: days .* 'MONkey'"):
        _tariff(tmp_path, MINIMAL + '[[band]]\nname = "peak"\nstart = "07:00"\nend = "09:00"\ndays = ["MONkey"]\nfactor = 2\n')
    ok = _tariff(tmp_path, MINIMAL + '[[band]]\nname = "peak"\nstart = "07:00"\nend = "09:00"\ndays = ["Monday", "TUE"]\nfactor = 2\n')
    assert ok.bands[0].days == frozenset({0, 1})


def test_the_minor_unit_must_be_the_currency_s(tmp_path):
    with pytest.raises(DataError, match=r"t.toml:2: minor_unit 2 does not fit JPY, whose minor unit is 0"):
        _tariff(tmp_path, 'currency = "JPY"\nminor_unit = 2\n[road_class.motorway]\ncar = 120\n')
    yen = _tariff(tmp_path, 'currency = "JPY"\nminor_unit = 0\n[road_class.motorway]\ncar = 120.5\n')
    assert yen.fee("x", "motorway", "car", dt.datetime(2026, 3, 2, tzinfo=UTC))[0] == Decimal("121")


def test_fees_keep_every_digit_until_the_one_rounding(tmp_path):
    """28-digit arithmetic would round 1.004999…9 (33 digits) up to 1.005 and then to 1.01: it must be 1.00. (Fees of
    at least a cent: a flat fee below the minor unit is refused.)"""
    t = _tariff(tmp_path, 'currency = "EUR"\n[road_class.motorway]\ncar = 1.00499999999999999999999999999999\n'
                          'van = 1.00333333333333333333333333333333\n'
                          '[[band]]\nname = "b"\nstart = "00:00"\nend = "12:00"\nfactor = 1.5\n')  # fmt: skip
    night, noon = dt.datetime(2026, 3, 2, 1, tzinfo=UTC), dt.datetime(2026, 3, 2, 13, tzinfo=UTC)
    assert t.fee("x", "motorway", "car", noon)[0] == Decimal("1.00")
    assert t.fee("x", "motorway", "van", night)[0] == Decimal("1.50")  # × 1.5 = 1.504999…995
    assert t.fee("x", "motorway", "car", night)[0] == Decimal("1.51")  # × 1.5 = 1.5074999…


def test_a_huge_fee_is_a_one_line_error(tmp_path):
    with pytest.raises(DataError, match="not below"):
        _tariff(tmp_path, 'currency = "EUR"\n[road_class.motorway]\ncar = 1e26\n')


def test_reordered_keys_give_the_same_fees(tmp_path):
    """The example tariff with its keys, tables and bands in another order charges the same at every hour of a week."""
    text = EXAMPLE.read_text()
    blocks = text.split("\n\n")
    head, rest = blocks[0].splitlines(), blocks[1:]
    reordered = "\n".join([head[0], *reversed(head[1:])]) + "\n\n" + "\n\n".join(
        "\n".join([b.splitlines()[0], *reversed(b.splitlines()[1:])]) for b in reversed(rest)) + "\n"  # fmt: skip
    a, b = load_tariff(str(EXAMPLE)), _tariff(tmp_path, reordered)
    assert reordered != text
    start = dt.datetime(2024, 5, 6, tzinfo=UTC)
    for hour in range(0, 7 * 24):
        when = start + dt.timedelta(hours=hour, minutes=17)
        for vc in ("car", "van", "truck"):
            for rc in ("motorway", "expressway"):
                assert a.fee("g", rc, vc, when) == b.fee("g", rc, vc, when)
