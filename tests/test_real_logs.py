"""The reader on real receiver logs: gpsd's regression suite and an Android log."""

from __future__ import annotations

from pathlib import Path

import pynmea2
import pytest
from conftest import SHARED_DATA, shared
from gpsd_chk import gpsd_fixes, our_fixes

from tollcli.readers.nmea import read_nmea

GPSD = SHARED_DATA / "gpsd"
GPSD_LOGS = sorted(GPSD.glob("*.log")) if GPSD.exists() else []
TOLERANCE_DEG = 1e-6


def _nmea_fix_sentences(log: Path) -> int:
    """Independent count (pynmea2) of checksum-valid GGA/RMC/GNS/GLL sentences reporting a fix."""
    count = 0
    for raw in log.read_bytes().split(b"\n"):
        text = raw.decode("latin-1").strip()
        start = text.rfind("$")
        if start < 0:
            continue
        try:
            msg = pynmea2.parse(text[start:], check=True)
        except (pynmea2.ParseError, ValueError, AttributeError, TypeError):
            continue
        kind = type(msg).__name__
        if (kind == "GGA" and str(msg.gps_qual) not in ("", "0") and msg.lat) or (
            kind in ("RMC", "GLL") and getattr(msg, "status", "") == "A" and msg.lat
        ) or (kind == "GNS" and msg.lat):
            count += 1
    return count


def test_gpsd_folder_present():
    shared("gpsd")
    assert len(GPSD_LOGS) == 177


@pytest.mark.parametrize("log", GPSD_LOGS, ids=lambda p: p.name)
def test_gpsd_log_reads_and_agrees_with_gpsd(log: Path):
    tables = read_nmea(log)  # must not raise, whatever the log holds
    stats = tables.stats
    assert stats.lines > 0
    assert len(tables.epochs) == stats.epochs
    # every satellite row belongs to an epoch of the table
    assert set(tables.satellites["epoch"]) <= set(tables.epochs["epoch"])
    assert tables.epochs["epoch"].is_monotonic_increasing
    chk = log.with_name(log.name + ".chk")
    if not chk.exists():
        return
    theirs = gpsd_fixes(chk)
    ours = our_fixes(tables.epochs)
    both = sorted(set(ours) & set(theirs))
    if theirs and not both:
        # Allowed exception, explained: gpsd decoded positions from a binary protocol
        # (SiRF, UBX, TSIP, GREIS, ...) that an NMEA 0183 reader does not read. Then the
        # log holds no NMEA sentence that reports a fix — checked independently with pynmea2.
        assert not ours
        assert _nmea_fix_sentences(log) == 0, "gpsd has NMEA fixes we missed"
        return
    agree = [k for k in both if abs(ours[k][0] - theirs[k][0]) <= TOLERANCE_DEG
             and abs(ours[k][1] - theirs[k][1]) <= TOLERANCE_DEG]  # fmt: skip
    assert len(agree) >= 0.99 * len(both), f"{len(both) - len(agree)} of {len(both)} epochs disagree"


def test_gpsd_comparison_covers_many_epochs():
    shared("gpsd")
    total = agree = 0
    for log in GPSD_LOGS:
        chk = log.with_name(log.name + ".chk")
        if not chk.exists():
            continue
        theirs, ours = gpsd_fixes(chk), our_fixes(read_nmea(log).epochs)
        for k in set(ours) & set(theirs):
            total += 1
            agree += abs(ours[k][0] - theirs[k][0]) <= TOLERANCE_DEG and abs(ours[k][1] - theirs[k][1]) <= TOLERANCE_DEG
    assert total > 1500
    assert agree / total >= 0.99


def test_gpsd_grs_residuals_follow_gsa_order():
    # quectel-L70: $GPGSA,A,3,04,09,16,26,07,03,27,02,...  $GPGRS,150119.000,1,-0.33,-2.59,3.03,-0.09,-2.98,7.12,-15.6,17.0
    tables = read_nmea(shared("gpsd", "quectel-L70.log"))
    sats = tables.satellites
    first = sats[(sats.epoch == 0) & sats.used].set_index("svid")["residual_m"]
    expected = {4: -0.33, 9: -2.59, 16: 3.03, 26: -0.09, 7: -2.98, 3: 7.12, 27: -15.6, 2: 17.0}
    assert first.to_dict() == expected


def test_gpsd_multi_constellation_nmea410():
    tables = read_nmea(shared("gpsd", "ublox-zed-f9p-nmea.log"))
    constellations = set(tables.satellites["constellation"])
    assert {"GPS", "GLONASS", "Galileo", "BeiDou"} <= constellations
    ep = tables.epochs.iloc[0]
    # first GSA cycle: used satellites across the four systems
    used = tables.satellites[(tables.satellites.epoch == ep.epoch) & tables.satellites.used]
    assert ep.n_used == len(used) > 12


def test_android_pixel6_48_epochs_no_satellites():
    tables = read_nmea(shared("android", "pixel6.nmea"))
    ep = tables.epochs
    assert len(ep) == 48
    assert ep["lat_deg"].notna().all() and ep["lon_deg"].notna().all()
    assert len(tables.satellites) == 0
    assert tables.stats.skipped == 0
    # first line: NMEA,$GPGGA,234257.00,3725.590397,N,12210.422534,W,... RMC date 071123
    assert ep["lat_deg"].iloc[0] == pytest.approx(37 + 25.590397 / 60, abs=1e-9)
    assert ep["lon_deg"].iloc[0] == pytest.approx(-(122 + 10.422534 / 60), abs=1e-9)
    assert str(ep["time_utc"].iloc[0]) == "2023-11-07 23:42:57+00:00"
