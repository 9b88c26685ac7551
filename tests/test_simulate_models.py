"""The simulator's pieces: orbits, streets, correlated errors, faults (known answers and properties)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tollcli.simulate.constellations import galileo_nominal, gps_nominal, gps_walker, orbit_period_s, sat_ecef
from tollcli.simulate.errors import FaultPlan, fault_epochs, gauss_markov
from tollcli.simulate.sky import sky
from tollcli.simulate.streets import ENVIRONMENTS, Side, Street, buildings, line_of_sight

SIDEREAL_DAY_S = 86_164.0905


def test_orbit_periods_are_the_nominal_ones():
    assert orbit_period_s(gps_nominal().a_m[0]) == pytest.approx(SIDEREAL_DAY_S / 2, abs=0.01)  # two orbits a sidereal day
    assert gps_nominal().a_m[0] == pytest.approx(26_561_750.0, abs=100.0)
    assert orbit_period_s(29_600_318.0) / 3600 == pytest.approx(14.08, abs=0.01)  # Galileo: 14 h 05 min


def test_gps_ground_track_repeats_every_sidereal_day():
    c = gps_nominal()
    a, b = sat_ecef(c, 1000.0), sat_ecef(c, 1000.0 + SIDEREAL_DAY_S)
    assert np.linalg.norm(a, axis=-1) == pytest.approx(c.a_m)
    assert np.max(np.linalg.norm(a - b, axis=-1)) < 50.0  # metres, after 2 orbits and one turn of the Earth
    assert np.min(np.linalg.norm(a - sat_ecef(c, 1000.0 + SIDEREAL_DAY_S / 2), axis=-1)) > 1e7  # half a day: elsewhere


def test_constellation_layout():
    gps, gal, walker = gps_nominal(), galileo_nominal(), gps_walker()
    assert gps.svid.size == 24 and gal.svid.size == 27 and walker.svid.size == 24
    assert sorted(set(np.round(gps.raan_deg, 3))) == pytest.approx(sorted((272.847 + 60 * np.arange(6)) % 360))
    assert np.unique(gal.raan_deg).size == 3 and set(gal.incl_deg) == {56.0}
    # Walker 27/3/1: in-plane spacing 40°, phase step 360·1/27 between planes
    u = gal.arg_lat_deg.reshape(3, 9)
    assert np.diff(u[0]) == pytest.approx(np.full(8, 40.0))
    assert (u[1, 0] - u[0, 0]) == pytest.approx(360 / 27)


def test_open_sky_visibility_matches_the_thesis():
    """Thesis Tables 7.2/7.3 (open air): GPS ≥ 7 in 94.57 % of epochs, Galileo 97.66 %; never fewer than 6."""
    t = np.arange(0, 86_164, 30.0)
    ones = np.ones(t.size)
    for c, published in ((gps_nominal(), 0.9457), (galileo_nominal(), 0.9766)):
        view = sky(c, t, 42.683 * ones, 2.883 * ones, 50.0 * ones)
        n = (view["elev_deg"] >= 5.0).sum(axis=1)
        assert n.min() >= 6
        assert np.mean(n >= 7) == pytest.approx(published, abs=0.03)


def _one_building(height_m: float, start_m: float = -30.0, end_m: float = 30.0) -> Street:
    side = Side(np.array([start_m]), np.array([end_m]), np.array([height_m]))
    return Street(ENVIRONMENTS["urban"], left=side, right=side)


@pytest.mark.parametrize(
    ("elev_deg", "azim_deg", "visible"),
    [
        (45.0, 90.0, True),  # ray at the façade (10 m away): 1.5 + 10 = 11.5 m > 10 m
        (40.0, 90.0, False),  # 1.5 + 8.39 = 9.89 m < 10 m
        (40.0, 270.0, False),  # the other side
        (10.0, 0.0, True),  # along the street axis: no façade in the way
        (40.0, 30.0, True),  # meets the façade 17.3 m ahead, past the building's end at 30 m? no: d = 20, offset 17.3
    ],
)
def test_line_of_sight_facade_model(elev_deg, azim_deg, visible):
    street = _one_building(10.0, -30.0, 30.0) if azim_deg != 30.0 else _one_building(30.0, 20.0, 60.0)
    got = line_of_sight(street, np.array([0.0]), np.array([0.0]), np.array([[elev_deg]]), np.array([[azim_deg]]))
    assert bool(got[0, 0]) is visible


def test_line_of_sight_through_a_gap_and_past_the_end():
    street = _one_building(25.0, 5.0, 40.0)
    # a satellite at azimuth 45° meets the façade 10 m ahead (inside the building): hidden
    hidden = line_of_sight(street, np.array([0.0]), np.array([0.0]), np.array([[30.0]]), np.array([[45.0]]))
    # 50 m further on the same ray meets the façade at 60 m: past the building, visible
    seen = line_of_sight(street, np.array([50.0]), np.array([0.0]), np.array([[30.0]]), np.array([[45.0]]))
    assert not hidden[0, 0] and seen[0, 0]


def test_buildings_follow_table_one():
    rng = np.random.default_rng(1)
    side = buildings(ENVIRONMENTS["urban"], 0.0, 200_000.0, rng)
    width = side.end_m - side.start_m
    gaps = side.start_m[1:] - side.end_m[:-1]
    assert side.height_m.min() >= 4.0 and side.height_m.max() <= 25.0
    assert side.height_m.mean() == pytest.approx(15.0, abs=0.1)
    assert width.min() >= 10.0
    assert np.mean(gaps > 0) == pytest.approx(0.1, abs=0.01)
    assert gaps[gaps > 0].min() >= 10.0
    # the truncated normal's mean: E[N(20, 25) | ≥ 10]
    expected = stats.truncnorm.mean((10 - 20) / 25, np.inf, loc=20, scale=25)
    assert width.mean() == pytest.approx(expected, rel=0.02)
    rural = buildings(ENVIRONMENTS["rural"], 0.0, 50_000.0, rng)
    rural_mean = stats.truncnorm.mean((4 - 6) / 1.5, (20 - 6) / 1.5, loc=6, scale=1.5)  # 6.27 m
    assert rural.height_m.mean() == pytest.approx(rural_mean, abs=0.05) and rural.height_m.min() >= 4.0
    assert buildings(ENVIRONMENTS["open"], 0.0, 1000.0, rng).start_m.size == 0


def test_gauss_markov_variance_and_correlation_time():
    rng = np.random.default_rng(7)
    u, last = gauss_markov(200_000, 3, 5.0, 1.0, rng)
    assert u.var(axis=0) == pytest.approx(np.ones(3), abs=0.03)
    lag1 = np.mean(u[1:] * u[:-1], axis=0)
    assert lag1 == pytest.approx(np.full(3, np.exp(-1 / 5)), abs=0.02)
    assert np.array_equal(last, u[-1])
    white, _ = gauss_markov(100_000, 1, 0.0, 1.0, rng)
    assert abs(np.mean(white[1:] * white[:-1])) < 0.01


def test_gauss_markov_continues_across_chunks():
    """E[u(k+1) | u(k)] = a·u(k) across a chunk boundary: regress over many seeds."""
    a = np.exp(-1 / 20)
    last, first_next = [], []
    for seed in range(400):
        rng = np.random.default_rng(seed)
        _, state = gauss_markov(50, 1, 20.0, 1.0, rng)
        nxt, _ = gauss_markov(1, 1, 20.0, 1.0, rng, state)
        last.append(state[0])
        first_next.append(nxt[0, 0])
    assert np.polyfit(last, first_next, 1)[0] == pytest.approx(a, abs=0.05)


def test_fault_epochs_at_given_times_and_by_probability():
    t = np.arange(0.0, 600.0)
    plan = FaultPlan(bias_m=50.0, at_s=[100.0, 400.0], duration_s=10.0)
    f = fault_epochs(plan, t, np.random.default_rng(0))
    assert f.sum() == 20 and f[100] and f[109] and not f[110] and f[400]
    long_t = np.arange(0.0, 200_000.0)
    share = fault_epochs(FaultPlan(bias_m=50.0, p_fault=0.05, duration_s=10.0), long_t, np.random.default_rng(1)).mean()
    assert share == pytest.approx(0.05 * (1 - 0.05 / 2), abs=0.01)  # overlapping episodes merge
    assert not fault_epochs(FaultPlan(bias_m=0.0, p_fault=0.5), t, np.random.default_rng(0)).any()
