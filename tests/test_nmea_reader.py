"""Reader behaviour on constructed logs: epochs, dates, dirty lines, chunking."""

from __future__ import annotations

import datetime as dt
import gzip
import io

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tollcli.errors import DataError
from tollcli.readers.nmea import compose, iter_nmea_tables, read_nmea
from tollcli.readers.nmea.dates import DateCarry, resolve_days
from tollcli.readers.nmea.fields import checksum


def _read(lines: list[str], **kw):
    return read_nmea(io.BytesIO(("\n".join(lines) + "\n").encode("latin-1")), **kw)


def test_round_trip_composed_drive():
    lines = list(compose.straight_drive(30))
    tables = _read(lines)
    ep = tables.epochs
    assert len(ep) == 30
    assert ep["speed_mps"].to_numpy() == pytest.approx(13.9, abs=1e-3)
    assert (ep["n_used"] == 11).all() and (ep["n_in_view"] == 11).all()
    assert ep["hdop"].iloc[0] == 0.9 and ep["pdop"].iloc[0] == 1.6 and ep["vdop"].iloc[0] == 1.3
    assert ep["sigma_major_m"].iloc[0] == 3.0 and ep["rms_residual_m"].iloc[0] == 2.1
    assert ep["time_utc"].iloc[0] == pd.Timestamp("2024-05-06T08:00:00Z")
    assert (np.diff(ep["time_utc"].to_numpy()).astype("timedelta64[ms]").astype(int) == 1000).all()
    # 10 m/s north-east over 29 s: latitude grows by 29*13.9*cos45/111132 deg
    assert ep["lat_deg"].iloc[-1] - ep["lat_deg"].iloc[0] == pytest.approx(29 * 13.9 * 0.70710678 / 111132, rel=1e-6)
    sats = tables.satellites
    assert len(sats) == 30 * 11
    gal = sats[sats.constellation == "Galileo"]
    assert set(gal.svid) == {2, 11, 24, 36} and (gal.signal_id == 7).all() and gal.used.all()


def test_midnight_rollover_forward_and_backward():
    day = dt.date(2014, 12, 31)
    lines = [
        compose.gga(86_398.0, 1.0, 2.0),  # before the first date: dated backwards
        compose.gga(86_399.0, 1.0, 2.0),
        compose.rmc(86_399.0, 1.0, 2.0, 1.0, 0.0, day),
        compose.gga(0.0, 1.0, 2.0),  # midnight: the next day without a new RMC
        compose.gga(1.0, 1.0, 2.0),
    ]
    got = _read(lines).epochs["time_utc"].astype(str).tolist()
    assert got == [
        "2014-12-31 23:59:58+00:00",
        "2014-12-31 23:59:59+00:00",
        "2015-01-01 00:00:00+00:00",
        "2015-01-01 00:00:01+00:00",
    ]


def test_backward_date_across_midnight():
    lines = [compose.gga(86_399.0, 1.0, 2.0), compose.gga(0.0, 1.0, 2.0), compose.zda(0.0, dt.date(2020, 3, 1))]
    got = _read(lines).epochs["time_utc"].astype(str).tolist()
    assert got == ["2020-02-29 23:59:59+00:00", "2020-03-01 00:00:00+00:00"]


def test_no_date_gives_nat_unless_date_given():
    lines = [compose.gga(10.0, 1.0, 2.0), compose.gga(11.0, 1.0, 2.0)]
    tables = _read(lines)
    assert tables.epochs["time_utc"].isna().all()
    assert tables.stats.undated_epochs == 2
    assert tables.epochs["tod_s"].tolist() == [10.0, 11.0]
    dated = _read(lines, date=dt.date(2021, 6, 1))
    assert dated.epochs["time_utc"].astype(str).tolist() == ["2021-06-01 00:00:10+00:00", "2021-06-01 00:00:11+00:00"]


@settings(max_examples=200, deadline=None)
@given(
    start=st.integers(0, 86_399),
    steps=st.lists(st.integers(1, 40_000), min_size=1, max_size=60),
    anchors=st.sets(st.integers(0, 60), max_size=5),
    split=st.integers(0, 60),
)
def test_resolve_days_recovers_true_dates(start, steps, anchors, split):
    """Property: with steps < 12 h and at least one anchor, every epoch gets its true date."""
    t = start + np.concatenate(([0], np.cumsum(steps))).astype(np.int64)
    true_days = 18_000 + t // 86_400
    tod = (t % 86_400).astype(float)
    anchor = np.full(t.size, -1, dtype=np.int64)
    idx = [a for a in anchors if a < t.size] or [t.size - 1]
    anchor[idx] = true_days[idx]
    if max(steps) >= 43_200:
        return  # rollover counting needs steps below half a day
    carry = DateCarry()
    cut = min(split, t.size)
    # the reader holds undated chunks until an anchor arrives: mimic that by splitting after one
    first_anchor = min(idx)
    cut = max(cut, first_anchor + 1)
    (a, jump_a), (b, jump_b) = resolve_days(tod[:cut], anchor[:cut], carry), resolve_days(tod[cut:], anchor[cut:], carry)
    assert (np.concatenate([a, b]) == true_days).all()
    assert np.isnan(np.concatenate([jump_a, jump_b])).all()  # true dates are never a jump


@pytest.mark.parametrize("cut", [0, 1, 50, 99])
@pytest.mark.parametrize("jump", [1, -1, -7168])
def test_a_date_jump_inside_a_continuous_trip_keeps_the_trips_date(cut, jump):
    """One RMC a day off, or a 1024-week rollover from the middle on: the trip's epochs keep its first date
    (midnight rollovers still counted), and the jump is kept where it happened; after a gap a new date is taken."""
    t = 86_300 + np.arange(200, dtype=np.int64)  # 1 Hz across midnight
    true_days = 20_000 + t // 86_400
    tod = (t % 86_400).astype(float)
    given = true_days.copy()
    given[60] += jump  # one epoch's RMC off
    given[120:] += jump  # from epoch 120 on, every RMC off (week-number rollover)
    carry = DateCarry()
    parts = [resolve_days(tod[:cut], given[:cut], carry), resolve_days(tod[cut:], given[cut:], carry)]
    days, jumps = (np.concatenate(x) for x in zip(*parts))
    assert (days == true_days).all()
    assert np.flatnonzero(np.isfinite(jumps)).tolist() == [60, *range(120, 200)] and (jumps[np.isfinite(jumps)] == jump).all()
    # the receiver off for an hour, then another date: taken as given
    later = np.concatenate([tod, tod[-1] + 3_600 + np.arange(3.0)])
    dates = np.concatenate([true_days, [true_days[-1] + 5] * 3])
    days, jumps = resolve_days(later, dates, DateCarry())
    assert days[-3:].tolist() == [true_days[-1] + 5] * 3 and np.isnan(jumps).all()


def test_dirty_lines_are_skipped_and_counted():
    good = list(compose.straight_drive(3))
    bad_checksum = good[0][:-2] + "00"
    lines = [
        "# a comment",
        "",
        "\x00\x01\xb5b\x01\x07binary junk" + good[0],  # binary bytes glued before a sentence: still decoded
        bad_checksum,
        good[2][:30],  # truncated, no checksum
        "hello world",  # not NMEA
        "!AIVDM,1,1,,A,13u?etPv2;0n:dDPwUM1U1Cb069D,0*24",  # AIS: valid but unused
        "NMEA," + good[2] + ",1699400577561",  # Android GnssLogger line
        compose.with_checksum("GPGGA,120000.00,9999.0,N,00000.0,E,1,05,1.0,1.0,M,0,M,,"),  # latitude out of range
        *good[3:],
    ]
    tables = _read(lines)
    s = tables.stats
    assert (s.comments, s.blank, s.bad_checksum, s.no_checksum, s.not_nmea, s.malformed) == (1, 1, 1, 1, 1, 1)
    assert s.unused == 1
    assert s.skipped == 4
    assert s.epochs == 3  # the malformed GGA opens no epoch of its own
    assert "line 4" in s.first_problem and "bad checksum" in s.first_problem


def test_strict_names_the_line():
    good = list(compose.straight_drive(2))
    lines = ["# header", good[0], good[1], good[2][:-2] + "00", *good[3:]]
    with pytest.raises(DataError, match=r":4: bad checksum"):
        _read(lines, strict=True)


def test_chunk_size_does_not_change_the_tables():
    lines = list(compose.straight_drive(50))
    data = ("\n".join(lines) + "\n").encode()
    whole = read_nmea(io.BytesIO(data))
    chunks = list(iter_nmea_tables(io.BytesIO(data), chunk_epochs=7, block_bytes=2000))
    assert len(chunks) > 5
    pd.testing.assert_frame_equal(whole.epochs, pd.concat([c.epochs for c in chunks], ignore_index=True))
    pd.testing.assert_frame_equal(whole.satellites, pd.concat([c.satellites for c in chunks], ignore_index=True))


def test_gzip_input(tmp_path):
    lines = list(compose.straight_drive(5))
    path = tmp_path / "log.nmea.gz"
    path.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    assert len(read_nmea(path).epochs) == 5


def test_nmea410_gsa_system_id_and_grs_matching():
    tod = 3600.0
    lines = [
        compose.gga(tod, 10.0, 20.0, n_used=5),
        compose.gsa([5, 7, 9], 2.0, 1.0, 1.5, system_id=1),
        compose.gsa([4, 12], 2.0, 1.0, 1.5, system_id=3),
        compose.grs(tod, [1.5, -2.0], system_id=3),  # Galileo residuals, listed first
        compose.grs(tod, [0.1, 0.2, 0.3], system_id=1),
        compose.rmc(tod, 10.0, 20.0, 5.0, 90.0, dt.date(2023, 1, 2)),
    ]
    tables = _read(lines)
    sats = tables.satellites.set_index(["constellation", "svid"])["residual_m"].to_dict()
    assert sats == {("GPS", 5): 0.1, ("GPS", 7): 0.2, ("GPS", 9): 0.3, ("Galileo", 4): 1.5, ("Galileo", 12): -2.0}
    assert tables.epochs["n_used"].iloc[0] == 5


def test_gsv_keeps_primary_signal_per_satellite():
    tod = 100.0
    lines = [
        compose.gga(tod, 10.0, 20.0),
        *compose.gsv([(5, 40.0, 100.0, 30.0)], "GP", signal_id=8),  # L5 first
        *compose.gsv([(5, 40.0, 100.0, 42.0)], "GP", signal_id=1),  # L1 C/A
    ]
    sats = _read(lines).satellites
    assert len(sats) == 1 and sats["cn0_dbhz"].iloc[0] == 42.0 and sats["signal_id"].iloc[0] == 1


def test_position_source_preference_and_invalid_fix():
    day = dt.date(2022, 2, 2)
    lines = [
        compose.rmc(10.0, 1.0, 1.0, 2.0, 10.0, day),
        compose.gga(10.0, 1.5, 1.5),  # GGA wins over RMC
        compose.rmc(11.0, 2.0, 2.0, 2.0, 10.0, day, status="V"),  # receiver says: no fix
    ]
    ep = _read(lines).epochs
    assert ep["lat_deg"].iloc[0] == pytest.approx(1.5) and bool(ep["fix_valid"].iloc[0])
    assert np.isnan(ep["lat_deg"].iloc[1]) and not bool(ep["fix_valid"].iloc[1])


_line = st.one_of(
    st.sampled_from(list(compose.straight_drive(2))),
    st.text(max_size=120),
    st.binary(max_size=120).map(lambda b: b.decode("latin-1")),
    st.builds(lambda s, f: compose.with_checksum(f"GP{s}," + ",".join(f)),
              st.sampled_from(["GGA", "RMC", "GSA", "GSV", "GST", "GRS", "GBS", "ZDA", "VTG", "GLL", "GNS"]),
              st.lists(st.sampled_from(["", "1", "-1", "99999999", "nan", "1e308", "A", "N", "123456.78", "x"]), max_size=22)),
)  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(st.lists(_line, max_size=40))
def test_any_lines_give_tables_not_exceptions(lines):
    text = "\n".join(lines).replace("\n\n", "\n")
    tables = read_nmea(io.BytesIO(text.encode("utf-8")))
    s = tables.stats
    assert len(tables.epochs) == s.epochs
    assert s.sentences == s.decoded + s.unused + s.malformed


def test_huge_integer_fields_are_malformed_not_crashes():
    # found by the nightly fuzz run: these overflowed the int8/int16 columns when a chunk was built
    lines = [
        compose.with_checksum("GPGGA,120000.00,4500.0,N,00700.0,E,99999999999,08,1.0,10.0,M,0,M,,"),
        compose.with_checksum("GPGSA,A,99999999999,01,02,03,04,,,,,,,,,1.0,1.0,1.0"),
        compose.with_checksum("GPGSV,1,1,01,99999999999,40,100,40"),
        compose.gga(10.0, 45.0, 7.0),
    ]
    tables = _read(lines)
    assert tables.stats.malformed == 3 and len(tables.epochs) == 1


@pytest.mark.parametrize("engine", ["bulk", "reference"])
def test_n_in_view_is_minus_one_without_gsv_and_zero_for_an_empty_gsv(engine):
    """An epoch without GSV has an unknown number of satellites in view (-1), unlike a GSV that lists none (0)."""
    gga = "$GPGGA,080000.00,4241.8033,N,00253.5785,E,1,05,1.0,49.3,M,0.0,M,,*"
    body = gga[1:-1]
    first = f"{gga}{checksum(body):02X}"
    second_body = body.replace("080000.00", "080001.00")
    empty_gsv = "GPGSV,1,1,00"
    lines = [first, f"${second_body}*{checksum(second_body):02X}", f"${empty_gsv}*{checksum(empty_gsv):02X}"]
    ep = _read(lines, date=dt.date(2026, 3, 2), engine=engine).epochs
    assert ep["n_in_view"].tolist() == [-1, 0]


@pytest.mark.parametrize("engine", ["bulk", "reference"])
def test_text_dropped_before_a_sentence_is_counted(engine):
    """Binary junk before a sentence, or a sentence glued behind another: the last sentence is read and the
    dropped text is counted and reported (never silently lost)."""
    good = list(compose.straight_drive(3))
    lines = [good[0], "\x00\x01junk" + good[1], *good[2:5], good[5] + good[6], *good[7:]]
    stats = _read(lines, engine=engine).stats
    assert stats.discarded_text == 2
    assert "text before the sentence dropped on 2 lines" in stats.summary()
    assert _read(good, engine=engine).stats.discarded_text == 0


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


@pytest.mark.parametrize("engine", ["bulk", "reference"])
def test_a_sentence_without_a_fix_is_not_malformed_for_its_placeholder_position(engine):
    """MediaTek chips write ``8960.000000`` (89°60′) and the date 05-01-1980 until their first fix
    (``mtk-3301.log``): a sentence that says it has no fix carries no position and no date, so those
    placeholders are neither read nor counted malformed; the same position with a fix is malformed."""
    no_fix = [
        _sentence("GPGGA,154512.414,8960.000000,N,00000.000000,E,0,0,,137.000,M,13.000,M,,"),
        _sentence("GPRMC,154512.414,V,8960.000000,N,00000.000000,E,0.000,0.00,050180,,,N"),
        _sentence("GPGLL,8960.000000,N,00000.000000,E,154512.414,V,N"),
        _sentence("GPGNS,154512.414,8960.000000,N,00000.000000,E,NN,00,,137.0,13.0,,"),
        _sentence("GPRMC,154513.414,A,5212.978993,N,00653.097906,E,0.052,0.00,230808,,,A"),
    ]
    tables = _read(no_fix, engine=engine)
    assert tables.stats.malformed == 0
    ep = tables.epochs
    assert len(ep) == 2 and np.isnan(ep["lat_deg"].iloc[0]) and not ep["fix_valid"].iloc[0]
    # the date of the fix, not the chip's 1980 guess, dates both epochs
    assert [str(t.date()) for t in ep["time_utc"]] == ["2008-08-23", "2008-08-23"]
    assert ep["date_jump_days"].isna().all()
    with_fix = [
        _sentence("GPGGA,154512.414,8960.000000,N,00000.000000,E,1,5,,137.000,M,13.000,M,,"),
        _sentence("GPRMC,154512.414,A,8960.000000,N,00000.000000,E,0.000,0.00,050180,,,A"),
        _sentence("GPGLL,8960.000000,N,00000.000000,E,154512.414,A,A"),
        _sentence("GPGNS,154512.414,8960.000000,N,00000.000000,E,AN,05,,137.0,13.0,,"),
    ]
    assert _read(with_fix, engine=engine).stats.malformed == 4
