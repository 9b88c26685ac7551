"""RINEX 3 observation + navigation input: orbits, atmosphere and the full WLS + RAIM path."""

from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, run_cli
from rinex_synth import make_rinex

from tollcli.geodesy import enu_rotation, geodetic2ecef
from tollcli.gnss.atmosphere import klobuchar_delay_m, saastamoinen_delay_m
from tollcli.gnss.orbits import MU_GPS, OMEGA_E, kepler_position_clock
from tollcli.gnss.rinex_positions import rinex_epochs
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim

A_GPS = 26_559_700.0


def _circular(toe_s: float, **over) -> dict[str, np.ndarray]:
    eph = {k: np.zeros(1) for k in ("SVclockBias", "SVclockDrift", "SVclockDriftRate", "Crs", "DeltaN", "M0", "Cuc",
                                     "Eccentricity", "Cus", "Cic", "Omega0", "Cis", "Io", "Crc", "omega", "OmegaDot",
                                     "IDOT", "group_delay_s")}  # fmt: skip
    eph.update(sqrtA=np.array([np.sqrt(A_GPS)]), toe_s=np.array([toe_s]), toc_s=np.array([toe_s]))
    eph.update({k: np.array([v]) for k, v in over.items()})
    return eph


def test_orbit_known_answers_for_a_circular_equatorial_orbit():
    toe = 2313 * 604_800.0  # start of a GPS week: Ω at toe is Ω0
    eph = _circular(toe)
    pos, clock = kepler_position_clock(eph, np.array([toe]), np.array([False]))
    assert pos[0] == pytest.approx([A_GPS, 0.0, 0.0], abs=1e-6) and clock[0] == 0.0
    quarter = 0.25 * 2 * np.pi * np.sqrt(A_GPS**3 / MU_GPS)  # a quarter period later, 90° on, seen from a turned Earth
    pos, _ = kepler_position_clock(eph, np.array([toe + quarter]), np.array([False]))
    turn = -OMEGA_E * quarter
    assert pos[0] == pytest.approx([-A_GPS * np.sin(turn), A_GPS * np.cos(turn), 0.0], abs=1e-3)


def test_orbit_inclination_and_relativistic_clock():
    toe = 2313 * 604_800.0
    eph = _circular(toe, Io=np.radians(55.0), M0=np.pi / 2, Eccentricity=0.01, SVclockBias=1e-4)
    pos, clock = kepler_position_clock(eph, np.array([toe]), np.array([False]))
    # at u = 90° the satellite is at its highest latitude: 55°
    assert np.degrees(np.arcsin(pos[0, 2] / np.linalg.norm(pos[0]))) == pytest.approx(55.0, abs=0.6)
    # Kepler's equation E = M + e sin E at M = 90°, and the clock's relativistic term F·e·√A·sin E
    ecc = np.pi / 2
    for _ in range(20):
        ecc = np.pi / 2 + 0.01 * np.sin(ecc)
    assert np.linalg.norm(pos[0]) == pytest.approx(A_GPS * (1 - 0.01 * np.cos(ecc)), rel=1e-12)
    assert clock[0] == pytest.approx(1e-4 - 4.442807633e-10 * 0.01 * np.sqrt(A_GPS) * np.sin(ecc), rel=1e-12)


def test_klobuchar_night_floor_and_saastamoinen_zenith():
    alpha, beta = (1.1176e-08, 1.4901e-08, -5.9605e-08, -1.1921e-07), (9.0112e04, 1.6384e04, -1.9661e05, -6.5536e04)
    # local midnight at the pierce point: the 5 ns night-time floor times the obliquity at zenith
    night = klobuchar_delay_m(0.0, 0.0, 90.0, 0.0, 0.0, alpha, beta)
    assert night == pytest.approx(299_792_458.0 * 5e-9 * (1 + 16 * (0.53 - 0.5) ** 3), rel=1e-9)
    day = klobuchar_delay_m(0.0, 0.0, 90.0, 0.0, 50_400.0, alpha, beta)  # 14:00 local: the daytime peak
    assert day > 2 * night
    assert klobuchar_delay_m(0.0, 0.0, 10.0, 0.0, 50_400.0, alpha, beta) > 2.5 * day  # slant
    # standard atmosphere at sea level, 45°, zenith: 2.307 m dry + 0.120 m wet
    assert saastamoinen_delay_m(45.0, 0.0, 90.0) == pytest.approx(2.4275, abs=2e-3)
    assert saastamoinen_delay_m(45.0, 0.0, -1.0) == 0.0


def _enu_error(epochs, lat, lon, h):
    ours = np.array(geodetic2ecef(epochs.lat_deg.to_numpy(), epochs.lon_deg.to_numpy(), epochs.height_m.to_numpy())).T
    truth = np.array(geodetic2ecef(lat, lon, h))
    return np.einsum("ij,ej->ei", enu_rotation(lat, lon), ours - truth)


def test_rinex_round_trip_recovers_the_receiver(tmp_path):
    obs, nav, rows = make_rinex(tmp_path, n_epochs=5)
    epochs, meas = rinex_epochs(str(obs), str(nav), sigma_model="constant", sigma_m=1.0)
    assert len(epochs) == 5 and (epochs["n_measurements"] == 14).all()
    enu = _enu_error(epochs, 42.6987, 2.8956, 60.0)
    assert np.abs(enu).max() < 0.01  # mm-level: the only error left is the 1 mm rounding of the file
    assert epochs["clock_bias_m"].to_numpy() == pytest.approx(120.0, abs=0.01)
    out = run_raim(meas, RaimParams("etc", fde=True))
    assert (out["raim_status"] == "valid").all() and (out["dof"] == 14 - 5).all()


def test_rinex_2_11_observations_give_the_rinex_3_positions(tmp_path):
    """The same observations written as RINEX 2.11 (C1, S1; a satellite list continued on a second line) and as
    RINEX 3 (C1C, S1C): the same epochs, positions and measurements — a change of format that must change nothing.
    (RINEX 2.11 was refused: "no GPS or Galileo L1/E1 code observations".)"""
    three, two = tmp_path / "three", tmp_path / "two"
    three.mkdir(), two.mkdir()
    obs3, nav3, _ = make_rinex(three, n_epochs=4, noise_m=0.5, seed=5)
    obs2, nav2, _ = make_rinex(two, n_epochs=4, noise_m=0.5, seed=5, version=2)
    assert obs2.read_text().startswith("     2.11")
    e3, m3 = rinex_epochs(str(obs3), str(nav3), sigma_model="nominal", sigma_m=5.0)
    e2, m2 = rinex_epochs(str(obs2), str(nav2), sigma_model="nominal", sigma_m=5.0)
    pd.testing.assert_frame_equal(e2, e3)
    assert np.array_equal(m2.sv, m3.sv) and np.allclose(m2.sigma_m, m3.sigma_m, equal_nan=True)
    assert (e2["n_measurements"] == 14).all() and np.abs(_enu_error(e2, 42.6987, 2.8956, 60.0)).max() < 5.0


def test_rinex_fault_is_excluded(tmp_path):
    obs, nav, rows = make_rinex(tmp_path, n_epochs=3, noise_m=0.5, seed=3)
    faulty = [(k, sv, pr + (80.0 if sv == "G11" else 0.0), c) for k, sv, pr, c in rows]
    import datetime as dt

    from rinex_synth import write_obs

    write_obs(obs, faulty, dt.datetime(2024, 5, 6, 8, 0, 0))
    epochs, meas = rinex_epochs(str(obs), str(nav), sigma_model="constant", sigma_m=1.0)
    out = run_raim(meas, RaimParams("etc", hal_m=20.0, fde=True))
    assert (out["raim_status"] == "excluded_valid").all(), out
    assert (out["excluded_sv"] == "G11").all()
    shifted = epochs.assign(
        lat_deg=epochs.lat_deg + np.degrees(out.fde_shift_n_m / 6_368_000.0),
        lon_deg=epochs.lon_deg + np.degrees(out.fde_shift_e_m / (6_388_000.0 * np.cos(np.radians(42.7)))),
    )
    before = np.hypot(*_enu_error(epochs, 42.6987, 2.8956, 60.0)[:, :2].T)
    after = np.hypot(*_enu_error(shifted, 42.6987, 2.8956, 60.0)[:, :2].T)
    assert (after < before).all() and after.max() < 3.0


def test_cli_rinex(tmp_path):
    obs, nav, _ = make_rinex(tmp_path, n_epochs=3)
    out = tmp_path / "raim.csv"
    proc = run_cli("integrity", str(obs), "--nav", str(nav), "-o", str(out), "--json", "--sigma-model", "constant", "--sigma", "1")
    assert proc.returncode == 0, proc.stderr.decode()
    assert json.loads(proc.stdout)["format"] == "rinex"  # recognised from the file's first line
    table = pd.read_csv(out)
    assert len(table) == 3 and set(table["raim_status"]) == {"valid"}
    missing_nav = run_cli("integrity", str(obs))
    assert missing_nav.returncode == 2 and b"--nav" in missing_nav.stderr
    bad_nav = tmp_path / "bad.24n"
    bad_nav.write_text("this is not RINEX\n")
    proc = run_cli("integrity", str(obs), "--nav", str(bad_nav))
    assert proc.returncode == 1 and b"Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_a_navigation_file_without_an_orbit_is_a_data_error_not_an_internal_one():
    """A RINEX navigation dataset whose records carry no orbit (neither Keplerian elements nor a GLONASS state
    vector: an SBAS-only file, say) is a clear DataError, where it was ``KeyError: ['sqrtA']``. (BeiDou and GLONASS
    files are read: tests/test_glonass_beidou.py.)"""
    import xarray as xr

    from tollcli.errors import DataError

    from tollcli.gnss.satellite_states import rinex_ephemeris_table

    with pytest.raises(DataError, match="no GPS, Galileo, BeiDou or GLONASS ephemerides"):
        rinex_ephemeris_table(xr.Dataset({"SVclockBias": (("time", "sv"), [[1e-4]])},
                                         coords={"time": [np.datetime64("2021-04-29T00:00")], "sv": ["C01"]}))


def test_several_navigation_files_are_read_as_one(tmp_path):
    """``--nav`` given twice (the GPS records in one file, the Galileo ones in another, one record in both): the same
    positions as the one file that holds them all; ``process`` records both files and ``verify`` re-runs it. (The
    last ``--nav`` used to win silently: Galileo alone here.)"""
    import datetime as dt

    from rinex_synth import constellation, write_nav

    obs, nav, _ = make_rinex(tmp_path, n_epochs=3, noise_m=0.5, seed=7)
    sats = constellation(dt.datetime(2024, 5, 6, 8, 0, 0))
    gps, galileo = tmp_path / "gps.24n", tmp_path / "gal.24n"
    write_nav(gps, [s for s in sats if s["sv"][0] == "G"])
    write_nav(galileo, [s for s in sats if s["sv"][0] == "E"] + [sats[0]])  # a GPS record broadcast in both
    whole, _ = rinex_epochs(str(obs), str(nav))
    split, _ = rinex_epochs(str(obs), [str(gps), str(galileo)])
    pd.testing.assert_frame_equal(split, whole)
    assert (whole["n_measurements"] == 14).all()
    one, _ = rinex_epochs(str(obs), str(galileo))
    assert (one["n_measurements"] < 14).all()  # what the last file alone gave

    geo, tariff = str(REPO / "geoobjects" / "example-geoobjects.geojson"), str(REPO / "geoobjects" / "example-tariff.toml")
    invoice = tmp_path / "inv.json"
    done = run_cli("process", str(obs), "--nav", str(gps), "--nav", str(galileo), "--geo", geo, "--tariff", tariff, "-q",
                   "-o", str(invoice))  # fmt: skip
    assert done.returncode == 0, done.stderr.decode()
    inputs = json.loads(invoice.read_text())["inputs"]
    assert [os.path.basename(p) for p in inputs["nav"]] == ["gps.24n", "gal.24n"] and len(inputs["nav_sha256"]) == 2
    assert run_cli("verify", str(invoice), "-q").returncode == 0
    single = tmp_path / "single.json"
    assert run_cli("process", str(obs), "--nav", str(nav), "--geo", geo, "--tariff", tariff, "-q", "-o", str(single)).returncode == 0
    assert isinstance(json.loads(single.read_text())["inputs"]["nav"], str)  # one file: recorded as before
    for value in (json.dumps(str(nav)), json.dumps([str(gps), str(galileo)])):  # files come from the command line only
        (tmp_path / "settings.toml").write_text(f"nav = {value}\n")
        done = run_cli("process", str(obs), "--config", str(tmp_path / "settings.toml"), "--geo", geo, "--tariff", tariff,
                       "-q", "-o", str(tmp_path / "c.json"))  # fmt: skip
        assert done.returncode == 2 and b"'nav' is not a setting" in done.stderr and not (tmp_path / "c.json").exists()
