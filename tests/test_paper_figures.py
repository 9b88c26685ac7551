"""The papers' simulation (thesis ch. 7) on a short run: published figures within tolerance, and properties.

The full 72 h reproduction is ``benchmarks/paper_figures.py`` (table in benchmarks/paper_figures/).
"""

from __future__ import annotations

import numpy as np
import pytest

from tollcli.integrity.raim import RaimParams
from tollcli.simulate.paper import missed_segment_probability, simulate_runs, visibility_table

HOURS = 6.0


@pytest.fixture(scope="module")
def runs():
    return {env: simulate_runs(env, HOURS, ["gps_sbas", "dual_sbas", "dual_if"], seed=2012) for env in ("rural", "urban")}


def _availability(run, hal=50.0):
    return float(np.mean(run.hpl_classic_m(RaimParams("classic", hal, 5e-5, 5e-3)) <= hal))


def test_visibility_near_the_thesis(runs):
    rural = visibility_table(runs["rural"][1]["GPS+Galileo"])
    urban = visibility_table(runs["urban"][1]["GPS+Galileo"])
    assert rural[5] == 1.0  # thesis Table 7.4: 100 %
    assert urban[4] == pytest.approx(0.9926, abs=0.03)
    gps_rural = visibility_table(runs["rural"][1]["GPS"])
    assert gps_rural[4] == pytest.approx(0.9895, abs=0.03)


def test_classic_availability_near_the_published_values(runs):
    """Paper 001 §VI, HAL 50, P_MD 5e-5, P_FA 5e-3: dual ≈ 100 % rural, ≈ 55 % urban (thesis 63 %); GPS ≈ 50 % and ≈ 7 %."""
    assert _availability(runs["rural"][0]["dual_sbas"]) > 0.99
    assert 0.35 < _availability(runs["urban"][0]["dual_sbas"]) < 0.75
    assert 0.3 < _availability(runs["rural"][0]["gps_sbas"]) < 0.85
    assert _availability(runs["urban"][0]["gps_sbas"]) < 0.15
    assert _availability(runs["urban"][0]["dual_sbas"], 25.0) < _availability(runs["urban"][0]["dual_sbas"], 50.0)


def test_etc_raim_validates_every_position_the_classic_one_does(runs):
    """With the exact thresholds, HPL ≤ HAL ⇒ Th_classic ≤ Th_ETC: the ETC valid set contains the classic one."""
    run = runs["urban"][0]["dual_if"]
    classic = run.valid(RaimParams("classic", 50.0, 5e-5, 5e-3))
    etc = run.valid(RaimParams("etc", 50.0, 5e-5, exact_threshold=True))
    assert classic.sum() > 100
    assert not np.any(classic & ~etc)
    assert etc.sum() > classic.sum()


def test_missed_segment_probability_falls_with_duration_and_etc_is_lower(runs):
    durations = np.arange(1, 41)
    run = runs["urban"][0]["dual_sbas"]
    classic, n = missed_segment_probability(run.valid(RaimParams("classic", 50.0, 5e-5, 5e-3)), durations)
    etc, _ = missed_segment_probability(run.valid(RaimParams("etc", 50.0, 5e-5)), durations)
    assert n[0] == HOURS * 3600 and n[-1] == HOURS * 3600 - 39
    assert np.all(np.diff(classic) <= 1e-4) and classic[-1] < classic[0]
    assert np.all(etc <= classic + 1e-12)
    # a window of 1 s is missed exactly when that epoch is not valid
    assert classic[0] == pytest.approx(1 - run.valid(RaimParams("classic", 50.0, 5e-5, 5e-3)).mean())


def test_missed_segment_probability_known_answer():
    valid = np.array([1, 0, 0, 0, 1, 0, 1, 1], dtype=bool)
    p, n = missed_segment_probability(valid, np.array([1, 2, 3, 4, 9]))
    assert list(n) == [8, 7, 6, 5, 0]
    assert p[:4] == pytest.approx([4 / 8, 2 / 7, 1 / 6, 0.0]) and np.isnan(p[4])
