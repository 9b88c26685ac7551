"""Topological map matching: point-to-curve with heading, and roads that do not connect."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tollcli.geodesy import enu_shift2geodetic
from tollcli.integrity.map_matching import delta_heading_deg, load_roads, match

START = (42.60, 2.88)


def _at(north_m, east_m=0.0):
    lat, lon = enu_shift2geodetic(START[0], START[1], east_m, north_m)
    return [float(lon), float(lat)]


def _roads(tmp_path, connector: bool):
    feats = [
        {"type": "Feature", "properties": {"id": "T", "tolled": True}, "geometry": {"type": "LineString", "coordinates": [_at(-100), _at(3000)]}},
        {"type": "Feature", "properties": {"id": "P", "tolled": False}, "geometry": {"type": "LineString", "coordinates": [_at(-100, 60), _at(3000, 60)]}},
    ]  # fmt: skip
    if connector:  # a slip road joining P to T at 1500 m
        feats.append({"type": "Feature", "properties": {"id": "C", "tolled": False},
                      "geometry": {"type": "LineString", "coordinates": [_at(1400, 60), _at(1500, 0)]}})  # fmt: skip
    path = tmp_path / "roads.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return load_roads(str(path))


def _drive(east_of_t_m, seconds=200, speed=13.89):
    t = np.arange(seconds, dtype=float)
    north = speed * t
    east = np.broadcast_to(np.asarray(east_of_t_m, float), t.shape)
    lat, lon = enu_shift2geodetic(START[0], START[1], east, north)
    course = np.degrees(np.arctan2(np.gradient(east), np.gradient(north))) % 360.0
    return pd.DataFrame({"time_utc": pd.Timestamp("2026-03-02T08:00:00Z") + pd.to_timedelta(t, unit="s"),
                         "lat_deg": lat, "lon_deg": lon, "speed_mps": speed, "course_deg": course})  # fmt: skip


def test_point_to_curve_picks_the_nearest_road(tmp_path):
    roads = _roads(tmp_path, connector=False)
    m = match(_drive(0.0), roads)
    assert set(m["matched_road"]) == {"T"}
    assert m["match_dist_m"].max() < 1.0 and m["delta_theta_deg"].max() < 1.0
    assert m["along_m"].iloc[100] == pytest.approx(100 + 100 * 13.89, abs=1.0)


def test_a_biased_fix_does_not_jump_to_an_unconnected_road(tmp_path):
    """Driving P (60 m east of T); from t = 60 s the fixes are pushed 55 m west, right next to T."""
    east = np.where(np.arange(200) >= 60, 5.0, 60.0)
    roads = _roads(tmp_path, connector=False)
    m = match(_drive(east), roads)
    assert set(m["matched_road"][:60]) == {"P"}
    assert set(m["matched_road"][60:]) == {"P"}  # T is nearer, but P and T do not connect
    assert m["match_dist_m"][60:].min() == pytest.approx(55.0, abs=1.0)


def test_a_connected_road_can_be_taken(tmp_path):
    """With a slip road the vehicle moves from P onto T — through the connector."""
    north = 13.89 * np.arange(200)
    east = np.interp(north, [1400.0, 1500.0], [60.0, 0.0])  # along the slip road between 1400 and 1500 m
    roads = _roads(tmp_path, connector=True)
    m = match(_drive(east), roads)
    roads_seen = list(dict.fromkeys(m["matched_road"]))
    assert roads_seen == ["P", "C", "T"]


def test_heading_difference_wraps_and_two_way_roads_take_the_nearer_direction():
    assert delta_heading_deg(350.0, 10.0, oneway=True) == pytest.approx(20.0)
    assert delta_heading_deg(0.0, 180.0, oneway=True) == pytest.approx(180.0)
    assert delta_heading_deg(0.0, 180.0, oneway=False) == pytest.approx(0.0)
    assert delta_heading_deg(0.0, 90.0, oneway=False) == pytest.approx(90.0)
