"""u-blox navigation messages read as the receiver's own solution: against pyubx2 on every real UBX log (the long
OSNMA recording against the raw-measurement reader, which is checked against pyubx2), against the receiver's NAV-PVT
on the OSNMA recording, and on constructed frames of every message read."""

from __future__ import annotations

import io
import math
import struct

import numpy as np
import pandas as pd
import pytest
from conftest import SHARED_DATA, run_cli, shared

from tollcli.integrity.raim import RaimParams
from tollcli.io.sources import format_of_head, sniff_format
from tollcli.job.log_integrity import iter_integrity
from tollcli.readers.nmea import ReadStats
from tollcli.readers.ubx_frames import frame
from tollcli.readers.ubx_nav import iter_ubx_nav_tables, svinfo_satellite

GPSD = SHARED_DATA / "gpsd"
OSNMA_UBX = SHARED_DATA / "osnma" / "ublox" / "current_config.ubx"


def _read(source, **kw):
    stats = ReadStats()
    chunks = list(iter_ubx_nav_tables(source, stats=stats, **kw))
    epochs = pd.concat([c.epochs for c in chunks], ignore_index=True) if chunks else pd.DataFrame()
    sats = pd.concat([c.satellites for c in chunks], ignore_index=True) if chunks else pd.DataFrame()
    return epochs, sats, stats


def _pyubx2_pvt(path) -> pd.DataFrame:
    from pyubx2 import UBX_PROTOCOL, UBXReader

    rows = []
    with open(path, "rb") as fh:
        for _, msg in UBXReader(fh, protfilter=UBX_PROTOCOL, quitonerror=0):
            if msg is not None and msg.identity == "NAV-PVT" and msg.fixType not in (0, 5):
                rows.append((float(msg.lat), float(msg.lon), int(msg.numSV), msg.hAcc / 1000.0))
    return pd.DataFrame(rows, columns=["lat", "lon", "n_sv", "h_acc_m"]).astype(float)


def _reference_pvt(path) -> pd.DataFrame:
    """The NAV-PVT fixes of a log as pyubx2 decodes them; of the long OSNMA recording (16 s in pyubx2) as the
    raw-measurement reader decodes them — itself checked against pyubx2 field by field (``test_ubx_reader.py``)."""
    if path != OSNMA_UBX:
        return _pyubx2_pvt(path)
    from tollcli.readers.ubx import read_ubx

    pvt = read_ubx(str(path)).pvt
    pvt = pvt[~pvt["fix_type"].isin([0, 5])]
    return pd.DataFrame({"lat": pvt["lat_deg"], "lon": pvt["lon_deg"], "n_sv": pvt["n_sv"], "h_acc_m": pvt["h_acc_m"]}).astype(float)


def _ubx_logs_with_pvt():
    if not GPSD.exists():
        return []
    return [p for p in sorted(GPSD.glob("*.log")) if b"\xb5\x62\x01\x07" in p.read_bytes()]


def test_every_real_nav_pvt_is_read_as_pyubx2_decodes_it():
    """Every gpsd log with NAV-PVT and the OSNMA recording: the epochs' positions, satellites used and hAcc are the
    NAV-PVT fields pyubx2 decodes, one epoch per fix, in order."""
    logs = _ubx_logs_with_pvt() + ([OSNMA_UBX] if OSNMA_UBX.exists() else [])
    if not logs:
        pytest.skip("real data not available: ../shared/data/gpsd, osnma")
    for log in logs:
        epochs, _, stats = _read(log)
        ours = epochs[epochs["lat_deg"].notna()]
        theirs = _reference_pvt(log)
        assert len(ours) == len(theirs), log.name
        assert np.allclose(ours["lat_deg"], theirs["lat"], atol=1e-9) and np.allclose(ours["lon_deg"], theirs["lon"], atol=1e-9), log.name
        assert (ours["n_used"].to_numpy() == theirs["n_sv"].to_numpy()).all(), log.name
        assert np.allclose(ours["sigma_major_m"], theirs["h_acc_m"]), log.name  # hAcc: the receiver's accuracy estimate
        assert stats.bad_checksum == 0 or log.name.startswith("ublox"), log.name


def test_the_osnma_recording_positions_are_nav_pvt_and_its_residuals_decide():
    """4 753 real epochs (NAV-PVT, NAV-SAT with prRes, NAV-TIMEGAL, SFRBX): every epoch has NAV-PVT's position and is
    decided at the residual level by the residual test on NAV-SAT's prRes of the satellites the fix used."""
    if not OSNMA_UBX.exists():
        pytest.skip("real data not available: ../shared/data/osnma/ublox/current_config.ubx")
    assert sniff_format(str(OSNMA_UBX)) == "ubx-nav"
    table = pd.concat([c.table for c in iter_integrity(str(OSNMA_UBX), "ubx-nav", RaimParams())], ignore_index=True)
    theirs = _reference_pvt(OSNMA_UBX)
    assert len(table) == 4753 == len(theirs)
    assert np.allclose(table["lat_deg"], theirs["lat"], atol=1e-9) and np.allclose(table["lon_deg"], theirs["lon"], atol=1e-9)
    assert (table["test_stat_source"] == "grs").all() and (table["integrity_source"] == "grs").all()
    assert (table["raim_status"] == "valid").mean() > 0.95  # a static receiver under open sky (the table: closing note)


def _nav_sat(itow: int, sats: list[tuple[int, int, int, int, int, float, bool]]) -> bytes:
    body = struct.pack("<IBBH", itow, 1, len(sats), 0)
    for gnss, sv, cno, elev, azim, pr_res, used in sats:
        body += struct.pack("<BBBbhhI", gnss, sv, cno, elev, azim, int(round(pr_res * 10)), 0x08 if used else 0x00)
    return frame(0x01, 0x35, body)


def _nav_pvt(itow: int, lat: float, lon: float, n_sv: int, h_acc_m: float = 1.5, second: int = 0, fix_type: int = 3,
             flags: int = 0x01) -> bytes:  # fmt: skip
    body = struct.pack("<IHBBBBBBIiBBBBiiiiII", itow, 2024, 5, 6, 12, 0, second, 0x07, 20, 0, fix_type, flags, 0, n_sv,
                       round(lon * 1e7), round(lat * 1e7), 100_000, 50_000, round(h_acc_m * 1000), 2000)  # fmt: skip
    body += struct.pack("<iiiiiIIH", 0, 0, 0, 25_000, 4_500_000, 300, 1000, 120) + bytes(92 - 78)
    return frame(0x01, 0x07, body)


SKY = [(0, 1, 45, 70, 10, 0.3), (0, 5, 44, 40, 80, -0.5), (0, 12, 42, 35, 160, 0.8), (0, 17, 40, 25, 230, -0.2),
       (2, 4, 43, 50, 300, 0.4), (2, 9, 39, 20, 20, -0.6), (0, 22, 38, 15, 120, 0.1), (2, 11, 41, 60, 200, -0.3)]  # fmt: skip


def _log(n_epochs: int, bias_sv: tuple[int, int] | None = None, bias_m: float = 0.0) -> bytes:
    out = b"# a comment line first, as gpsd's logs start\n$GPTXT,01,01,02,u-blox*00\n"
    for k in range(n_epochs):
        itow = 1000 * (43_200 + k)
        sats = [(g, s, c, e, a, r + (bias_m if (g, s) == bias_sv else 0.0), True) for g, s, c, e, a, r in SKY]
        out += _nav_sat(itow, sats) + _nav_pvt(itow, 42.7 + k * 1e-5, 2.9, len(sats), second=k % 60)
    return out


def test_constructed_nav_pvt_and_nav_sat_after_text_are_one_epoch_each_with_their_residuals():
    data = _log(3)
    assert format_of_head(data) == "ubx-nav"  # recognised after the comment and the NMEA text line
    epochs, sats, stats = _read(io.BytesIO(data))
    assert len(epochs) == 3 and len(sats) == 24 and stats.bad_checksum == 0
    assert epochs["time_utc"].iloc[0] == pd.Timestamp("2024-05-06T12:00:00.000020", tz="UTC").floor("ms")
    assert (epochs["fix_quality"] == 1).all() and (epochs["fix_mode"] == 3).all() and epochs["fix_valid"].all()
    assert math.isclose(epochs["speed_mps"].iloc[0], 25.0) and math.isclose(epochs["course_deg"].iloc[0], 45.0)
    first = sats[sats["epoch"] == 0]
    assert first["used"].all() and np.allclose(first["residual_m"], [r for *_, r in SKY])
    assert set(first["constellation"]) == {"GPS", "Galileo"}


def test_a_60_m_bias_on_one_used_satellites_prres_is_detected_at_the_residual_level(tmp_path):
    """The must-show of the UBX pattern: +60 m on one used satellite's prRes → fault_detected, decided by the residual
    test; without it, valid."""
    clean, biased = tmp_path / "clean.ubx", tmp_path / "biased.ubx"
    clean.write_bytes(_log(40))
    biased.write_bytes(_log(40, bias_sv=(0, 12), bias_m=60.0))
    for log, expected in ((clean, "valid"), (biased, "fault_detected")):
        table = pd.concat([c.table for c in iter_integrity(str(log), "ubx-nav", RaimParams())], ignore_index=True)
        assert (table["integrity_source"] == "grs").all(), log.name
        assert (table["raim_status"] == expected).all(), (log.name, table["raim_status"].value_counts())


def test_nav_sol_posllh_svinfo_dop_hnr_and_pl_are_read():
    """Older and automotive receivers: NAV-SOL (ECEF, week) + NAV-POSLLH + NAV-SVINFO (legacy numbering, prRes in cm) +
    NAV-DOP + NAV-PL; HNR-PVT where there is no NAV position."""
    from tollcli.geodesy import geodetic2ecef

    x, y, z = (round(v * 100) for v in geodetic2ecef(48.0, 11.0, 600.0))
    itow, week = 302_400_000, 2300
    sol = struct.pack("<IihBBiiiIiiiIHBBI", itow, 0, week, 3, 0x0F, x, y, z, 250, 0, 0, 0, 50, 150, 0, 7, 0)
    posllh = struct.pack("<IiiiiII", itow, 110_000_000, 480_000_000, 600_000, 553_000, 1800, 3000)
    svinfo = struct.pack("<IBBH", itow, 2, 0, 0) + struct.pack("<BBBBBbhi", 0, 7, 0x01, 7, 44, 60, 90, -120)
    svinfo += struct.pack("<BBBBBbhi", 1, 215, 0x00, 4, 30, 20, 270, 999)  # Galileo E05, not used
    dop = struct.pack("<IHHHHHHH", itow, 200, 180, 100, 150, 90, 60, 70)
    pl = struct.pack("<BBbBBBBBIIIII", 1, 1, -7, 1, 1, 0, 0, 0, 0, itow, 3000, 4000, 9000) + bytes(40 - 28)
    data = b"".join([frame(0x01, 0x06, sol), frame(0x01, 0x02, posllh), frame(0x01, 0x30, svinfo), frame(0x01, 0x04, dop),
                     frame(0x01, 0x62, pl)])  # fmt: skip
    epochs, sats, _ = _read(io.BytesIO(data))
    e = epochs.iloc[0]
    assert math.isclose(e["lat_deg"], 48.0, abs_tol=1e-7) and math.isclose(e["lon_deg"], 11.0, abs_tol=1e-7)
    gps_s = week * 604_800 + itow / 1000 - 18  # UTC = GPS − 18 s in 2024
    assert e["time_utc"] == pd.Timestamp("1980-01-06", tz="UTC") + pd.Timedelta(seconds=gps_s)
    assert e["n_used"] == 7 and math.isclose(e["hdop"], 0.9) and math.isclose(e["pdop"], 1.8) and e["fix_quality"] == 2
    assert math.isclose(e["alt_m"], 553.0) and math.isclose(e["geoid_sep_m"], 47.0)
    # NAV-PL: 5 m horizontal at TIR 1e-7 → σ = 5 / √(−2 ln 1e-7) = 0.88 m < hAcc 1.8 m: hAcc stays the larger bound
    assert math.isclose(e["sigma_major_m"], 1.8)
    assert list(zip(sats["constellation"], sats["svid"], sats["used"])) == [("GPS", 7, True), ("Galileo", 5, False)]
    assert math.isclose(sats["residual_m"].iloc[0], -1.2) and np.isnan(sats["residual_m"].iloc[1])
    assert svinfo_satellite(70) == ("GLONASS", 6) and svinfo_satellite(130) == ("SBAS", 130)
    hnr = struct.pack("<IHBBBBBBiBBHiiiiiiiiIIIII", 1000, 2024, 5, 6, 12, 0, 1, 0x03, 0, 4, 0x01, 0, 115_000_000,
                      475_000_000, 500_000, 452_000, 20_000, 20_000, 9_000_000, 0, 2500, 4000, 300, 100_000, 0)  # fmt: skip
    epochs, sats, _ = _read(io.BytesIO(frame(0x28, 0x02, hnr)))
    assert len(epochs) == 1 and math.isclose(epochs["lat_deg"].iloc[0], 47.5) and sats.empty
    assert math.isclose(epochs["speed_mps"].iloc[0], 20.0) and math.isclose(epochs["sigma_major_m"].iloc[0], 2.5)


def test_damaged_frames_are_skipped_and_counted_and_strict_names_the_message(tmp_path):
    data = bytearray(_log(3))
    at = data.find(b"\xb5\x62\x01\x07")
    data[at + 30] ^= 0xFF  # a flipped byte in the first NAV-PVT: its checksum fails
    log = tmp_path / "damaged.ubx"
    log.write_bytes(bytes(data))
    epochs, _, stats = _read(log)
    assert stats.bad_checksum == 1 and len(epochs) == 2  # the first epoch's NAV-SAT had no position left
    proc = run_cli("integrity", str(log), "--strict", "-q", "-o", str(tmp_path / "i.csv"))
    err = proc.stderr.decode()
    assert proc.returncode == 1 and "damaged.ubx: UBX message 2" in err and "bad checksum" in err and "Traceback" not in err
    proc = run_cli("integrity", str(log), "-o", str(tmp_path / "i.csv"))
    assert proc.returncode == 0 and "1 bad checksum" in proc.stderr.decode()


def test_a_real_ubx_log_with_a_comment_header_is_recognised():
    """``ublox-glo.log`` (NAV-PVT + NAV-SAT + SFRBX) was read as NMEA ("no NMEA sentences"); the gpsd logs open with
    '#' comment lines: UBX is recognised after them."""
    if not GPSD.exists():
        pytest.skip("real data not available: ../shared/data/gpsd")
    assert sniff_format(str(shared("gpsd", "ublox-glo.log"))) == "ubx-nav"
    with_header = [p for p in _ubx_logs_with_pvt() if p.read_bytes().startswith(b"#")]
    assert with_header and all(sniff_format(str(p)) == "ubx-nav" for p in with_header)
