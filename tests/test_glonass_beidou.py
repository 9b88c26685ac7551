"""GLONASS and BeiDou from a u-blox receiver's own navigation data (``RXM-SFRBX``) and from RINEX 3: decoded,
their orbits computed, their pseudoranges used.

Known answers from real receivers (gpsd's regression logs and rtklibexplorer's triple-band walk): the satellites'
azimuth and elevation as the receiver itself reported them (NAV-SAT, in gpsd's ``.chk`` SKY reports) against those
of the decoded orbits at the receiver's position; a BeiDou-only position against the GPS + Galileo one of the same
epochs. Properties: a GLONASS orbit integrated forward and back returns to its start; a string with one wrong bit,
or subframes out of sequence, give no ephemeris.
"""

from __future__ import annotations

import collections
import json

import numpy as np
import pandas as pd
import pytest
from conftest import shared
from rinex_multi import write_nav, write_obs

from tollcli.geodesy import enu_rotation, geodetic2ecef
from tollcli.gnss import beidou_d1, glonass_strings, raw_positions
from tollcli.gnss.glonass_orbits import glonass_position_clock
from tollcli.gnss.rinex_positions import rinex_epochs
from tollcli.gnss.satellite_states import load_navigation, satellite_states
from tollcli.gnss.sigma_models import NominalModel
from tollcli.gnss.ubx_measurements import rawx_measurements, sfrbx_ephemerides
from tollcli.readers.gps_time import gps_seconds, leap_seconds_at_gps
from tollcli.readers.ubx import read_ubx, subframe_words

WALK = ("rtklibexplorer", "gnss_1730.ubx")
LETTER = {0: "G", 2: "E", 3: "C", 6: "R"}


@pytest.fixture(scope="module")
def walk():
    """The walk's u-blox log, read once."""
    return read_ubx(str(shared(*WALK)))


def _sky_against_orbits(log) -> pd.DataFrame:
    """Each satellite the receiver reported above the horizon (gpsd's SKY) that has a decoded orbit: its reported
    azimuth and elevation (whole degrees) and those of the orbit at the receiver's nearest NAV-PVT position."""
    ubx = read_ubx(str(log))
    eph = sfrbx_ephemerides(ubx)
    pvt = ubx.pvt[ubx.pvt["fix_type"] >= 2]
    when = pd.to_datetime(dict(year=pvt["year"], month=pvt["month"], day=pvt["day"], hour=pvt["hour"], minute=pvt["minute"],
                               second=pvt["second"]))  # fmt: skip
    rows = []
    for line in open(str(log) + ".chk", encoding="utf-8", errors="replace"):
        if '"class":"SKY"' not in line or '"satellites"' not in line:
            continue
        sky = json.loads(line)
        t = pd.Timestamp(sky["time"]).tz_localize(None)
        gps = float(gps_seconds(np.array([t.to_datetime64()]))[0])
        gps += float(leap_seconds_at_gps(np.array([gps]))[0])
        k = int(np.argmin(np.abs((when - t).dt.total_seconds().to_numpy())))
        for s in sky["satellites"]:
            sv = "%s%02d" % (LETTER.get(s.get("gnssid"), "?"), s.get("svid", 0))
            if sv[0] in "CR" and s.get("el", -1) > 0 and sv in set(eph["sv"]):
                rows.append((sv, gps, k, s["az"], s["el"]))
    q = pd.DataFrame(rows, columns=["sv", "gps", "k", "az_rx", "el_rx"])
    state = satellite_states(eph, q["sv"].to_numpy(str), q["gps"].to_numpy(float), np.full(len(q), 2.2e7))
    lat, lon, h = (pvt[c].to_numpy(float)[q["k"].to_numpy()] for c in ("lat_deg", "lon_deg", "height_m"))
    rx = np.stack(geodetic2ecef(lat, lon, h), -1)
    rot = np.stack([np.asarray(enu_rotation(a, b), float).reshape(3, 3) for a, b in zip(lat, lon)])
    enu = np.einsum("kij,kj->ki", rot, state["pos_m"] - rx)
    q["az"] = np.degrees(np.arctan2(enu[:, 0], enu[:, 1])) % 360
    q["el"] = np.degrees(np.arcsin(enu[:, 2] / np.linalg.norm(enu, axis=1)))
    rows = q[state["have"]]
    out = rows.copy()
    out["d_az"] = ((out["az"] - out["az_rx"] + 180) % 360 - 180).abs()
    out["d_el"] = (out["el"] - out["el_rx"]).abs()
    return out


def test_glonass_strings_of_a_real_receiver_pass_their_hamming_code_and_one_wrong_bit_fails():
    ubx = read_ubx(str(shared("gpsd", "ublox-glo.log")))
    words = subframe_words(ubx.sfrbx, 4)[0]
    strings = glonass_strings.decode_strings(words)
    assert len(strings) == 584 and strings["ok"].all()
    assert set(strings["m"]) == set(range(1, 16))  # the 15 strings of a frame
    rng = np.random.default_rng(3)
    for _ in range(40):  # any one data or check bit wrong (bits 1–84 of the 85)
        flipped = words.copy()
        row, bit = rng.integers(len(words)), int(rng.integers(1, 85))
        flipped[row, bit // 32] ^= np.uint32(1 << (31 - bit % 32))
        assert not glonass_strings.decode_strings(flipped[row : row + 1])["ok"][0]


def test_glonass_orbits_are_where_the_receiver_saw_the_satellites():
    """ublox-glo.log: the 4 GLONASS ephemerides decoded, each satellite's azimuth and elevation from its integrated
    orbit within the receiver's own whole-degree rounding (≤ 2° of azimuth, ≤ 1° of elevation) at every SKY report
    over the log's quarter of an hour."""
    seen = _sky_against_orbits(shared("gpsd", "ublox-glo.log"))
    assert seen["sv"].nunique() == 4 and len(seen) > 2000
    assert seen["d_az"].max() <= 2.0 and seen["d_el"].max() <= 1.0


def test_beidou_and_glonass_of_a_zed_f9p_are_where_it_saw_them():
    seen = _sky_against_orbits(shared("gpsd", "ublox-zed-f9p-sfrbx.log"))
    assert set(seen["sv"].str[0]) == {"C", "R"}
    assert seen["d_az"].max() <= 2.0 and seen["d_el"].max() <= 1.0


def test_a_glonass_orbit_integrated_forward_and_back_returns_to_its_start():
    ubx = read_ubx(str(shared("gpsd", "ublox-glo.log")))
    eph = sfrbx_ephemerides(ubx)
    fields = {c: eph[c].to_numpy(float) for c in eph.columns if c != "sv"}
    start, _ = glonass_position_clock(fields, fields["toe_s"])
    assert np.allclose(start, eph[["X", "Y", "Z"]].to_numpy(float))
    ahead, clock = glonass_position_clock(fields, fields["toe_s"] + 900.0)
    moved = dict(fields, X=ahead[:, 0], Y=ahead[:, 1], Z=ahead[:, 2])
    # the velocity at +900 s by a central difference, then back 900 s: the start again
    plus, _ = glonass_position_clock(fields, fields["toe_s"] + 900.5)
    minus, _ = glonass_position_clock(fields, fields["toe_s"] + 899.5)
    vel = plus - minus
    moved.update(dX=vel[:, 0], dY=vel[:, 1], dZ=vel[:, 2], toe_s=fields["toe_s"] + 900.0)
    back, _ = glonass_position_clock(moved, fields["toe_s"])
    assert np.abs(back - start).max() < 0.05  # m (the difference quotient's own error)
    assert 2.5e7 < np.linalg.norm(ahead, axis=1).min() and np.linalg.norm(ahead, axis=1).max() < 2.6e7
    assert np.allclose(clock, fields["SVclockBias"] + fields["SVrelFreqBias"] * 900.0)


def test_beidou_d1_ephemerides_of_a_triple_band_receiver(walk):
    """The walk's B3I D1 subframes: 8 medium-orbit satellites (√A ≈ 5 282.6 √m), their seconds of week and clock
    times consistent; subframes out of sequence join into nothing."""
    ubx = walk
    eph = sfrbx_ephemerides(ubx)
    beidou = eph[eph["sv"].str.startswith("C")]
    assert len(beidou) == 8
    assert np.allclose(beidou["sqrtA"], 5282.6, atol=0.1)
    sub = ubx.sfrbx[(ubx.sfrbx["gnssId"] == 3) & (ubx.sfrbx["sigId"] == 4)].reset_index(drop=True)
    assert len(beidou_d1.ephemerides(sub)) == 8
    words = subframe_words(sub, 10)[0]
    frn = beidou_d1.decode_subframes(words)["frn"].to_numpy()
    shuffled = sub[frn != 2].reset_index(drop=True)  # no subframe 2: no ephemeris
    assert beidou_d1.ephemerides(shuffled).empty


def test_beidou_positions_agree_with_gps_and_galileo(monkeypatch, walk):
    """The walk solved with BeiDou alone lies within a few metres of GPS + Galileo alone (two independent sets of
    satellites, orbits and clocks); with every system the solution uses BeiDou's pseudoranges too."""
    ubx = walk
    rawx, eph = rawx_measurements(ubx), sfrbx_ephemerides(ubx)
    every_system = raw_positions.BROADCAST_CONSTELLATIONS

    def solved(systems):
        monkeypatch.setattr(raw_positions, "BROADCAST_CONSTELLATIONS", systems)
        return raw_positions.raw_epochs(raw_positions.with_broadcast_satellites(rawx, eph), "nominal", 5.0, NominalModel())

    gps_gal, _ = solved(("GPS", "Galileo"))
    beidou, _ = solved(("BeiDou",))
    _every, meas = solved(every_system)
    a = np.stack(geodetic2ecef(gps_gal["lat_deg"], gps_gal["lon_deg"], gps_gal["height_m"]), -1)
    b = np.stack(geodetic2ecef(beidou["lat_deg"], beidou["lon_deg"], beidou["height_m"]), -1)
    rot = np.asarray(enu_rotation(float(gps_gal["lat_deg"][0]), float(gps_gal["lon_deg"][0])), float).reshape(3, 3)
    horizontal = np.hypot(*((b - a) @ rot.T)[:, :2].T)
    assert len(horizontal) == 536 and np.median(horizontal) < 5.0 and np.percentile(horizontal, 95) < 10.0
    used = collections.Counter(s[0] for s in meas.sv[meas.mask])
    assert used["C"] > 3500 and used["G"] > 6000 and used["E"] > 8000  # BeiDou: B3I (B1C and B2a need B-CNAV delays)


@pytest.mark.parametrize("log", ["ublox-x20p.log", "ublox-zed-f9p-sfrbx.log", "ublox-glo.log", "ublox-ned-m8t-sbfrx3.log"])
def test_every_gpsd_ubx_log_with_navigation_data_decodes(log):
    eph = sfrbx_ephemerides(read_ubx(str(shared("gpsd", log))))
    assert len(eph) and eph["toc_s"].notna().all()


def test_rinex_navigation_of_every_system_gives_the_decoded_orbits(tmp_path, walk):
    """Round trip through RINEX 3.04: the ephemerides decoded from two real receivers (the walk's GPS, Galileo and
    BeiDou; ublox-glo.log's GLONASS) written in each system's RINEX layout and time (BDT, UTC and km for GLONASS),
    read back as two ``--nav`` files at once, place every satellite where the decoded ones do (to the file's 12
    digits)."""
    walk = sfrbx_ephemerides(walk)
    glo = sfrbx_ephemerides(read_ubx(str(shared("gpsd", "ublox-glo.log"))))
    write_nav(tmp_path / "walk.nav", walk)
    write_nav(tmp_path / "glo.nav", glo)
    both, _ = load_navigation([str(tmp_path / "walk.nav"), str(tmp_path / "glo.nav")])
    assert collections.Counter(s[0] for s in both["sv"]) == collections.Counter(s[0] for s in pd.concat([walk, glo])["sv"])
    for table in (walk, glo):
        sv, t = table["sv"].to_numpy(str), table["toc_s"].to_numpy(float) + 600.0
        a = satellite_states(table, sv, t, np.full(sv.size, 2.2e7))
        b = satellite_states(both, sv, t, np.full(sv.size, 2.2e7))
        assert (a["have"] == b["have"]).all() and a["have"].sum() >= 4
        assert np.abs(a["pos_m"] - b["pos_m"])[a["have"]].max() < 1e-3
        assert np.abs(a["clock_s"] - b["clock_s"])[a["have"]].max() < 1e-15


def test_rinex_observations_with_beidou_solve_as_the_ubx_log_does(tmp_path, walk):
    """The walk's RAWX code pseudoranges written as RINEX 3.04 (GPS and Galileo C1C, BeiDou B3I C6I) with its decoded
    navigation (its first 30 s): every epoch solved with BeiDou's measurements among them, within a few metres of the
    u-blox path's
    solution of the same epochs (which uses every band)."""
    ubx = walk
    write_nav(tmp_path / "walk.nav", sfrbx_ephemerides(ubx))
    rawx = rawx_measurements(ubx)
    first = rawx[rawx["t_rx_gps_s"] <= rawx["t_rx_gps_s"].min() + 30.0]  # its first 30 s (georinex reads slowly)
    assert write_obs(tmp_path / "walk.obs", first) == 121
    epochs, meas = rinex_epochs(str(tmp_path / "walk.obs"), str(tmp_path / "walk.nav"))
    used = collections.Counter(s[0] for s in meas.sv[meas.mask])
    assert len(epochs) == 121 and used["C"] > 800 and used["G"] > 450 and used["E"] > 600
    assert sorted(set(meas.clock_index[meas.mask].tolist())) == [0, 1, 2]  # one clock per system
    ubx_epochs, _ = raw_positions.raw_epochs(raw_positions.with_broadcast_satellites(rawx_measurements(ubx), sfrbx_ephemerides(ubx)),
                                             "nominal", 5.0, NominalModel())  # fmt: skip
    a = np.stack(geodetic2ecef(epochs["lat_deg"], epochs["lon_deg"], epochs["height_m"]), -1)
    b = np.stack(geodetic2ecef(ubx_epochs["lat_deg"], ubx_epochs["lon_deg"], ubx_epochs["height_m"]), -1)[:121]
    rot = np.asarray(enu_rotation(float(epochs["lat_deg"][0]), float(epochs["lon_deg"][0])), float).reshape(3, 3)
    horizontal = np.hypot(*((a - b) @ rot.T)[:, :2].T)
    assert np.median(horizontal) < 3.0 and horizontal.max() < 8.0
