"""The distance ``info`` says a log's vehicle drove: against the reference trajectories in ../shared/data, from the
receiver's speed where it gave one, and unchanged by what must not change it (noise on the fixes, chunking)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SAMPLES, run_cli, shared

from tollcli.geodesy import ecef2geodetic, great_circle_distance_m
from tollcli.job.distance_driven import SPEED_GAP_S, DistanceCarry, add_distance, distance_from


def _info(path) -> dict:
    proc = run_cli("info", str(path), "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    return json.loads(proc.stdout)


def _length_m(lat, lon) -> float:
    return float(great_circle_distance_m(lat[:-1], lon[:-1], lat[1:], lon[1:]).sum())


def test_the_berlin_drive_is_as_long_as_its_reference_trajectory():
    """Its snapshot fixes (errors of 15–45 m, 5 Hz) summed to 8.24 km; the reference trajectory is 1.55 km long."""
    rows = [line.split() for line in shared("smartloc", "Berlin_Potsdamer_Platz_GT.txt").read_text().splitlines() if line.startswith("point3")]
    xyz = np.array([[float(v) for v in r[2:5]] for r in rows])
    lat, lon, _ = ecef2geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    info = _info(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt"))
    assert info["distance_m"] == pytest.approx(_length_m(lat, lon), rel=0.02)
    assert info["distance_from"] == "speed"  # the odometer's


def test_the_ublox_walk_is_as_long_as_its_rtk_track():
    """Doppler speed: 130 m for 129 m; the snapshot fixes summed to 247 m."""
    rows = [line.split() for line in shared("rtklibexplorer", "gnss_1730_sf.pos").read_text().splitlines() if not line.startswith("%")]
    lat, lon = np.array([float(r[2]) for r in rows]), np.array([float(r[3]) for r in rows])
    info = _info(shared("rtklibexplorer", "gnss_1730.ubx"))
    assert info["distance_m"] == pytest.approx(_length_m(lat, lon), rel=0.03)


def test_a_straight_drive_at_a_known_speed():
    info = _info(SAMPLES / "straight-drive.nmea")
    assert info["distance_m"] == pytest.approx(179 * 13.9, rel=0.01) and info["distance_from"] == "speed"


def test_a_standing_receiver_drives_nowhere_however_its_fixes_jitter():
    """meinberg-gps164.log: 70 fixes over 89 s that wander 87 m in all, speed 0 throughout."""
    info = _info(shared("gpsd", "meinberg-gps164.log"))
    assert info["distance_m"] < 1.0


def _drive(seed: int, n: int = 600):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.choice([1.0, 1.0, 1.0, 2.0, 30.0], n))  # gaps the speed cannot bridge among them
    speed = np.abs(rng.normal(12.0, 4.0, n))
    north = np.cumsum(np.r_[0.0, np.diff(t) * (speed[1:] + speed[:-1]) / 2])
    lat, lon = 48.0 + north / 111_132.0, np.full(n, 11.0)
    return t, lat, lon, speed


@pytest.mark.parametrize("seed", range(5))
def test_noise_on_the_fixes_moves_only_the_intervals_without_speed(seed):
    t, lat, lon, speed = _drive(seed)
    clean, noisy = DistanceCarry(), DistanceCarry()
    add_distance(clean, t, lat, lon, speed)
    jitter = np.random.default_rng(100 + seed).normal(0.0, 30.0 / 111_132.0, lat.size)
    add_distance(noisy, t, lat + jitter, lon, speed)
    gaps = np.diff(t) > SPEED_GAP_S
    assert clean.by_fixes == noisy.by_fixes == int(gaps.sum()) > 0
    assert noisy.distance_m == pytest.approx(clean.distance_m, abs=gaps.sum() * 4 * 30.0)  # each gap's step, ±2×2σ per end
    none_missing = DistanceCarry()
    add_distance(none_missing, t[: np.argmax(gaps)], lat[: np.argmax(gaps)], lon[: np.argmax(gaps)], speed[: np.argmax(gaps)])
    jittered = DistanceCarry()
    cut = int(np.argmax(gaps))
    add_distance(jittered, t[:cut], lat[:cut] + jitter[:cut], lon[:cut], speed[:cut])
    assert jittered.distance_m == none_missing.distance_m  # where the speed covers every interval, the fixes do not count


@pytest.mark.parametrize("seed", range(5))
def test_chunked_is_whole(seed):
    t, lat, lon, speed = _drive(seed)
    lat[np.random.default_rng(seed).random(lat.size) < 0.1] = np.nan  # epochs without a position
    speed[np.random.default_rng(seed + 7).random(lat.size) < 0.1] = np.nan
    whole, chunked = DistanceCarry(), DistanceCarry()
    add_distance(whole, t, lat, lon, speed)
    edges = np.sort(np.random.default_rng(seed).choice(np.arange(1, t.size), 9, replace=False))
    for a, b in zip(np.r_[0, edges], np.r_[edges, t.size]):
        add_distance(chunked, t[a:b], lat[a:b], lon[a:b], speed[a:b])
    assert chunked.distance_m == pytest.approx(whole.distance_m, rel=1e-12)
    assert (chunked.by_speed, chunked.by_fixes) == (whole.by_speed, whole.by_fixes)
    assert distance_from(whole).startswith("speed (") and distance_from(whole, "the smoothed trajectory").endswith("the smoothed trajectory")
