"""The simulator's town drives: corners rounded and taken at a driver's sideways acceleration, stops, and tours of
a real street map (``--tour``, ``--turn-radius``)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from conftest import run_cli, shared

from tollcli.simulate.route import ACCEL_MPS2, LATERAL_ACCEL_MPS2, along_route, round_corners

HELSINKI = ("osm", "helsinki.osm.pbf")


def test_a_right_angle_becomes_an_arc_tangent_to_both_legs():
    """Known answer: an L of two 100 m legs and a 10 m radius: the path keeps its ends, every point of the corner is
    10 m from the arc's centre (90, 10), and no step turns the heading by more than a few degrees."""
    xy = round_corners(np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]]), 10.0)
    np.testing.assert_allclose(xy[0], [0.0, 0.0])
    np.testing.assert_allclose(xy[-1], [100.0, 100.0])
    arc = xy[1:-1]
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 90.0, arc[:, 1] - 10.0), 10.0, atol=1e-9)
    heading = np.degrees(np.arctan2(*np.diff(xy, axis=0).T[::-1]))
    assert np.abs(np.diff(heading)).max() < 10.0
    short = round_corners(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]), 10.0)  # legs too short: a smaller arc
    assert np.hypot(*(short[1] - [2.0, 0.0])) < 1e-9


def _drive(turn_radius_m, stops=()):
    """A square block of 200 m sides driven twice round at 13.89 m/s, 10 Hz."""
    lon0, lat0, d = 24.94, 60.17, 200.0 / 111_320.0
    k = 1.0 / np.cos(np.radians(lat0))
    ring = [(lon0, lat0), (lon0 + d * k, lat0), (lon0 + d * k, lat0 + d), (lon0, lat0 + d), (lon0, lat0)]
    return along_route([shapely.LineString(ring + ring[1:])], 13.89, 10.0, None, stops=list(stops), turn_radius_m=turn_radius_m)


def test_turns_are_taken_at_a_drivers_sideways_acceleration_and_stops_stand_still():
    """Property: with rounded corners the vehicle slows for each (speed × turn rate ≤ LATERAL_ACCEL_MPS2), brakes
    and pulls away no harder than ACCEL_MPS2, reaches its cruising speed on the straights and stands still through a
    stop; at full speed through sharp corners (no radius) the sideways acceleration is far beyond any car's."""
    traj = _drive(10.0, stops=[(30.0, 10.0)])
    t, v = traj.t_s, traj.speed_mps
    turn = np.gradient(np.unwrap(np.radians(traj.heading_deg)), t)
    sideways = np.abs(v * turn)
    assert np.percentile(sideways, 99) <= LATERAL_ACCEL_MPS2 * 1.15
    assert np.abs(np.diff(v) / np.diff(t)).max() <= ACCEL_MPS2 * 1.02  # (the 0.01 s integration steps)
    assert v.max() == pytest.approx(13.89, abs=0.01) and v[(t > 31.0) & (t < 39.0)].max() == 0.0
    assert traj.s_m[-1] == pytest.approx(1600.0, rel=0.02)  # the rounded corners cut a little off
    sharp = _drive(None)
    sharp_turn = np.abs(sharp.speed_mps * np.gradient(np.unwrap(np.radians(sharp.heading_deg)), sharp.t_s))
    assert sharp_turn.max() > 10 * LATERAL_ACCEL_MPS2


def test_a_tour_of_a_real_street_map_is_driven_with_its_turns(tmp_path):
    """``--tour`` on Helsinki's streets: the same seed the same drive (byte-identical files), another seed another;
    the drive turns (its heading covers every direction) and slows for it."""
    osm = shared(*HELSINKI)
    common = ["simulate", "--route", str(osm), "--from", "60.1710,24.9440", "--tour", "3000", "--turn-radius", "10",
              "--stop-at", "60", "--stop-duration", "20", "--rate", "2", "--duration", "300", "-q"]  # fmt: skip
    for name, seed in (("a", "4"), ("b", "4"), ("c", "5")):
        proc = run_cli(*common, "--seed", seed, "-o", str(tmp_path / name))
        assert proc.returncode == 0, proc.stderr.decode()
    truth = {n: (tmp_path / n / "truth.csv").read_bytes() for n in "abc"}
    assert truth["a"] == truth["b"] and truth["a"] != truth["c"]
    import pandas as pd

    drive = pd.read_csv(tmp_path / "a" / "truth.csv")
    assert np.histogram(drive["heading_deg"], bins=4, range=(0, 360))[0].min() > 0
    assert 0.0 < drive["speed_mps"].median() < 13.89


def test_route_options_refuse_what_cannot_be_driven(tmp_path):
    """One-line errors: --from and --to on the same point of the network (was a traceback), --tour without a map."""
    proc = run_cli("simulate", "--route", str(shared(*HELSINKI)), "--from", "60.1710,24.9440", "--to", "60.1710,24.9440",
                   "-o", str(tmp_path / "x"), "-q")  # fmt: skip
    err = proc.stderr.decode()
    assert proc.returncode == 1 and "same point of the road network" in err and "Traceback" not in err and err.count("\n") == 1
    proc = run_cli("simulate", "--tour", "3000", "-o", str(tmp_path / "y"), "-q")
    assert proc.returncode == 2 and "need a --route" in proc.stderr.decode()
