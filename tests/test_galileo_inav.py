"""Galileo I/NAV from u-blox RXM-SFRBX: the real page pairs of two receivers (X20P, ZED-F9P) pass their CRC and
decode into orbits that point where the receivers themselves saw the satellites; round trip through pyubx2;
a UBX log with GPS and Galileo runs the full path on its own."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from conftest import shared
from tollcli.geodesy import great_circle_distance_m
from tollcli.gnss.inav_words import FIELDS, PI_GPS, RINEX_NAMES, decode_pages, encode_pages
from tollcli.gnss.orbits import EPHEMERIS_FIELDS, kepler_position_clock
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.satellite_states import satellite_states
from tollcli.gnss.sigma_models import NominalModel
from tollcli.gnss.ubx_measurements import sfrbx_ephemerides
from tollcli.readers.gps_time import gps_seconds
from tollcli.readers.ubx import read_ubx, subframe_words

C = 299_792_458.0
LOGS = ("ublox-x20p", "ublox-zed-f9p-sfrbx")


def _ubx(name):
    return read_ubx(str(shared("gpsd", f"{name}.log")))


def _inav_words(ubx):
    sf = ubx.sfrbx
    sf = sf[(sf["gnssId"] == 2) & sf["sigId"].isin([1, 5])]
    return sf, subframe_words(sf, 8)[0].astype(np.uint64)


@pytest.mark.parametrize("name", LOGS)
def test_every_real_page_pair_passes_its_crc_and_one_flipped_bit_fails_it(name):
    sf, words = _inav_words(_ubx(name))
    pages = decode_pages(words)
    assert len(pages) >= 29 and pages["valid"].all()
    assert set(pages["word_type"]) >= {0, 1, 2, 3, 4, 5}
    rng = np.random.default_rng(7)
    for _ in range(20):  # a bit anywhere the CRC covers (or in the CRC itself) → the page is refused
        k, bit = rng.integers(len(words)), int(rng.choice(np.r_[2:114, 130:128 + 106]))
        damaged = words[k : k + 1].copy()
        damaged[0, bit // 32] ^= np.uint64(1 << (31 - bit % 32))
        assert not decode_pages(damaged)["valid"].iloc[0]


def test_real_ephemerides_are_galileo_orbits_of_their_day():
    """E07, E08, E26 (X20P, IODnav 91) and E21 (ZED-F9P, IODnav 42): MEO at 29 600 km, 56° inclination, healthy,
    dated by their own GST week (the X20P on 2026-03-07, the ZED-F9P on 2020-06-10 as its NAV-PVT says)."""
    x20p, zed = sfrbx_ephemerides(_ubx("ublox-x20p")), sfrbx_ephemerides(_ubx("ublox-zed-f9p-sfrbx"))
    gal_x, gal_z = x20p[x20p["sv"].str.startswith("E")], zed[zed["sv"].str.startswith("E")]
    assert sorted(gal_x["sv"]) == ["E07", "E08", "E26"] and (gal_x["iode"] == 91).all()
    assert gal_z["sv"].tolist() == ["E21"] and gal_z["iode"].tolist() == [42]
    both = pd.concat([gal_x, gal_z])
    assert (both["sqrtA"] ** 2).between(29.5e6, 29.7e6).all()
    assert np.degrees(both["Io"]).between(54, 58).all() and (both["Eccentricity"] < 0.01).all()
    assert (both["health"] == 0).all() and (both["SVclockBias"].abs() < 1e-3).all()
    day = lambda t: str(pd.Timestamp("1980-01-06") + pd.Timedelta(seconds=float(t)))[:10]  # noqa: E731
    assert {day(t) for t in gal_x["toe_s"]} == {"2026-03-07"} and day(gal_z["toe_s"].iloc[0]) == "2020-06-10"
    assert x20p["sv"].str.startswith("G").sum() >= 5  # the GPS LNAV ephemerides of the same log stay


def _gpsd_sky(name):
    """(time, sv, az_deg, el_deg) of every satellite in gpsd's SKY reports (the receiver's NAV-SAT)."""
    rows = []
    for line in open(shared("gpsd", f"{name}.log.chk"), encoding="latin-1"):
        if line.startswith('{"class":"SKY"') and '"satellites"' in line:
            sky = json.loads(line)
            for s in sky["satellites"]:
                if "az" in s and "el" in s and s["gnssid"] in (0, 2):
                    rows.append((sky["time"], "GE"[s["gnssid"] // 2] + f"{s['svid']:02d}", s["az"], s["el"]))
    return pd.DataFrame(rows, columns=["time", "sv", "az_deg", "el_deg"]).drop_duplicates()


def _az_el(lat_deg, lon_deg, sat_m):
    """Azimuth and elevation (deg) of satellites (…, 3) seen from spherical-Earth points (broadcast over both)."""
    la, lo = np.radians(lat_deg)[..., None], np.radians(lon_deg)[..., None]
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la) * np.ones_like(lo)], -1)
    east = np.stack([-np.sin(lo), np.cos(lo), np.zeros_like(lo * la)], -1)
    north = np.cross(up, east)
    los = sat_m - 6_371_000.0 * up
    los = los / np.linalg.norm(los, axis=-1, keepdims=True)
    e, n, u = (los * east).sum(-1), (los * north).sum(-1), (los * up).sum(-1)
    return np.degrees(np.arctan2(e, n)) % 360, np.degrees(np.arcsin(u))


def _mismatch_deg(az, el, sky):
    daz = (az - sky["az_deg"].to_numpy() + 180) % 360 - 180
    return np.hypot(daz * np.cos(np.radians(el)), el - sky["el_deg"].to_numpy())


@pytest.mark.parametrize("name", LOGS)
def test_decoded_galileo_orbits_point_where_the_receiver_saw_the_satellites(name):
    """The receiver's own azimuth and elevation (NAV-SAT, whole degrees, as gpsd reports it) of each Galileo
    satellite at the last SKY report, against the decoded orbit seen from the receiver: within 1.5°. The ZED-F9P
    log has its fix; the X20P log has none, so its site is found from the GPS satellites' directions alone (our
    LNAV orbits, already checked against gpsd) and the Galileo ones are then predicted from it."""
    eph = sfrbx_ephemerides(_ubx(name))
    sky = _gpsd_sky(name)
    sky = sky[(sky["time"] == sky["time"].iloc[-1]) & sky["sv"].isin(eph["sv"])]
    t_gps = gps_seconds(pd.to_datetime(sky["time"].str.rstrip("Z")).to_numpy()) + 18
    st = satellite_states(eph, sky["sv"].to_numpy(), t_gps, np.full(len(sky), 2.3e7))
    assert st["have"].all()
    gps = sky["sv"].str.startswith("G").to_numpy()
    galileo = ~gps
    assert galileo.sum() >= 1
    if name == "ublox-zed-f9p-sfrbx":  # the fix it reports (gpsd TPV)
        lat0, lon0 = 44.0688649, -121.3140956
    else:  # coarse then fine grid over the globe for the GPS directions
        assert gps.sum() >= 5
        lat, lon = np.meshgrid(np.arange(-89.5, 90, 1.0), np.arange(-179.5, 180, 1.0), indexing="ij")
        for _ in range(2):
            az, el = _az_el(lat, lon, st["pos_m"][gps])
            best = np.unravel_index(np.argmin((_mismatch_deg(az, el, sky[gps]) ** 2).sum(-1)), lat.shape)
            lat0, lon0 = lat[best], lon[best]
            lat, lon = np.meshgrid(lat0 + np.arange(-1, 1, 0.02), lon0 + np.arange(-1, 1, 0.02), indexing="ij")
    az, el = _az_el(np.array(lat0), np.array(lon0), st["pos_m"])
    miss = _mismatch_deg(az, el, sky)
    assert (miss[gps] < 1.5).all(), miss[gps]
    assert miss[galileo].max() < 1.5, dict(zip(sky["sv"][galileo], miss[galileo]))


def _real_galileo():
    tables = [sfrbx_ephemerides(_ubx(n)) for n in LOGS]
    table = pd.concat(tables, ignore_index=True)
    return table[table["sv"].str.startswith("E")].reset_index(drop=True)


def test_inav_round_trip_through_pyubx2_gives_the_same_orbit(tmp_path):
    """Each real ephemeris → word types 1–5 (page pairs with CRC) → RXM-SFRBX built by pyubx2 → our reader: every
    field back to half its LSB, the orbit and clock equal within 1 mm over ±2 h; a page with a damaged CRC drops
    its satellite (no ephemeris from four word types)."""
    from pyubx2 import GET, UBXMessage

    source = _real_galileo()
    stream = bytearray()
    for k, row in source.iterrows():
        eph = row.to_dict()
        for j, page in enumerate(encode_pages(eph, float(row["toe_s"]) - 30)):
            if k == 0 and j == 2:
                page = page.copy()
                page[6] ^= 1  # a CRC bit of E-first's word type 3
            stream += UBXMessage("RXM", "RXM-SFRBX", GET, gnssId=2, svId=int(row["sv"][1:]), sigId=1, numWords=8,
                                 version=2, **{f"dwrd_{i + 1:02d}": int(w) for i, w in enumerate(page)}).serialize()  # fmt: skip
    path = tmp_path / "inav.ubx"
    path.write_bytes(bytes(stream))
    ubx = read_ubx(str(path))
    assert ubx.n_bad == 0 and len(ubx.sfrbx) == 5 * len(source)
    decoded = sfrbx_ephemerides(ubx)
    assert source["sv"].iloc[0] not in set(decoded["sv"])
    source = source.iloc[1:]
    decoded = decoded.set_index("sv").loc[source["sv"]]
    lsb = {name: scale * (PI_GPS if semi else 1.0) for name, _, _, _, _, scale, semi in FIELDS}
    for rinex, field in RINEX_NAMES.items():
        diff = np.abs(decoded[rinex].to_numpy(float) - source[rinex].to_numpy(float))
        assert (diff <= 0.5 * lsb[field] * (1 + 1e-9) + 1e-15).all(), (rinex, diff.max(), lsb[field])
    for name in ("toe_s", "toc_s", "health", "iode"):
        np.testing.assert_array_equal(decoded[name].to_numpy(float), source[name].to_numpy(float))
    t = source["toe_s"].to_numpy(float)[:, None] + np.linspace(-7200, 7200, 9)[None, :]
    keys = (*EPHEMERIS_FIELDS, "toc_s", "toe_s", "group_delay_s")
    pa, ca = kepler_position_clock({k: np.repeat(source[k].to_numpy(float)[:, None], 9, 1) for k in keys}, t, np.ones(t.shape, bool))
    pb, cb = kepler_position_clock({k: np.repeat(decoded[k].to_numpy(float)[:, None], 9, 1) for k in keys}, t, np.ones(t.shape, bool))
    assert np.linalg.norm(pa - pb, axis=-1).max() < 1e-3
    assert np.abs(ca - cb).max() * C < 1e-3


def test_a_ubx_log_with_gps_and_galileo_runs_the_full_path_on_its_own(tmp_path):
    """A receiver simulated on the X20P log's own real orbits (its GPS LNAV and three Galileo I/NAV
    ephemerides, at the log's time, at the site its GPS directions point to): RAWX + SFRBX of both systems →
    every Galileo measurement gets its decoded orbit and is used; positions within 2.5 m."""
    from ubx_synth import simulate_ubx

    table = sfrbx_ephemerides(_ubx("ublox-x20p"))
    t0 = float(table.loc[table["sv"].str.startswith("E"), "toe_s"].iloc[0]) + 600
    lat, lon = 40.62, -3.62
    path = tmp_path / "gps_galileo.ubx"
    path.write_bytes(simulate_ubx(table, t0, 10, lat, lon, 650.0))
    epochs, meas = pseudorange_epochs(str(path), "ubx", None, "nominal", 5.0, NominalModel())
    assert len(epochs) == 10
    galileo = np.char.startswith(meas.sv.astype(str), "E") & meas.mask
    assert (galileo.sum(axis=1) == 3).all(), galileo.sum(axis=1)  # E07, E08, E26 in every epoch
    assert (epochs["n_measurements"] >= 8).all(), epochs["n_measurements"].tolist()
    err = great_circle_distance_m(epochs["lat_deg"].to_numpy(), epochs["lon_deg"].to_numpy(), lat, lon)
    assert err.max() < 2.5, err
    gps_only = tmp_path / "gps_only.ubx"  # the same drive without Galileo orbits: three measurements fewer
    gps_only.write_bytes(simulate_ubx(table[table["sv"].str.startswith("G")], t0, 10, lat, lon, 650.0))
    fewer, _ = pseudorange_epochs(str(gps_only), "ubx", None, "nominal", 5.0, NominalModel())
    assert (epochs["n_measurements"].to_numpy() - fewer["n_measurements"].to_numpy() == 3).all()
