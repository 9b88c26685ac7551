"""Known answers for the field converters and satellite numbering."""

import datetime as dt
import math

import pytest

from tollcli.readers.nmea import fields
from tollcli.readers.nmea.satellite_ids import satellite_id


def test_checksum_known_sentence():
    # from gpsd's bu353s4.log
    assert fields.checksum("GPGGA,030719.000,3747.0873,S,17518.8938,E,1,08,1.1,59.9,M,23.7,M,,0000") == 0x7D


@pytest.mark.parametrize(
    "text, hemi, expected",
    [("3747.0873", "S", -(37 + 47.0873 / 60)), ("0000.0000", "N", 0.0), ("8959.9999", "N", 89 + 59.9999 / 60), ("", "N", math.nan)],
)
def test_latitude(text, hemi, expected):
    got = fields.lat_deg(text, hemi)
    assert (math.isnan(got) and math.isnan(expected)) or got == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("text", ["9100.0000", "4560.0000", "-123.4", "abc"])
def test_latitude_out_of_range_is_malformed(text):
    with pytest.raises(ValueError):
        fields.lat_deg(text, "N")


def test_longitude_west_and_range():
    assert fields.lon_deg("12210.422534", "W") == pytest.approx(-(122 + 10.422534 / 60), abs=1e-12)
    with pytest.raises(ValueError):
        fields.lon_deg("18100.0", "E")
    with pytest.raises(ValueError):
        fields.lon_deg("01000.0", "X")


def test_time_of_day_and_leap_second():
    assert fields.time_of_day_s("030719.000") == 3 * 3600 + 7 * 60 + 19
    assert fields.time_of_day_s("235960.00") == 86_400.0  # leap second 23:59:60
    for bad in ("246000", "236100", "12", "ab0000"):
        with pytest.raises(ValueError):
            fields.time_of_day_s(bad)


def test_rmc_date_pivot_and_validation():
    epoch = dt.date(1970, 1, 1)
    assert fields.rmc_date_days("010170") == (dt.date(2070, 1, 1) - epoch).days  # 70 → 2070
    assert fields.rmc_date_days("311299") == (dt.date(1999, 12, 31) - epoch).days  # 99 → 1999
    assert fields.rmc_date_days("010180") == (dt.date(1980, 1, 1) - epoch).days  # 80 → 1980
    with pytest.raises(ValueError):
        fields.rmc_date_days("310224")  # 31 February
    assert fields.rmc_date_days("") == -1
    with pytest.raises(ValueError):
        fields.civil_days(99_999_999_999, 4, 2019)  # found by the nightly fuzz run: an OverflowError escaped


def test_numbers_reject_nan_and_inf():
    for bad in ("nan", "inf", "-Infinity"):
        with pytest.raises(ValueError):
            fields.num(bad)


@pytest.mark.parametrize(
    "hint, prn, expected",
    [
        (None, 5, ("GPS", 5)),
        (None, 40, ("SBAS", 127)),
        (None, 70, ("GLONASS", 6)),
        (None, 195, ("QZSS", 3)),
        (None, 305, ("Galileo", 5)),
        (None, 410, ("BeiDou", 10)),
        ("GLONASS", 70, ("GLONASS", 6)),
        ("Galileo", 12, ("Galileo", 12)),
        ("BeiDou", 12, ("BeiDou", 12)),
        ("BeiDou", 212, ("BeiDou", 12)),
        ("QZSS", 2, ("QZSS", 2)),
        ("NavIC", 4, ("NavIC", 4)),
    ],
)
def test_satellite_numbering(hint, prn, expected):
    assert satellite_id(hint, prn) == expected
