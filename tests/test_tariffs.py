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
