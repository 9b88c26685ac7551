"""Map-matching integrity (Binjammaz 2015): the rule table, the worked cases, the breakpoints."""

from __future__ import annotations

import numpy as np
import pytest

from tollcli.integrity.fuzzy_mm import RULES, SCORES, alarm, integrity_scale, memberships

REPRESENTATIVE = {"theta": {"good": 30.0, "bad": 120.0}, "d": {"low": 3.0, "average": 6.0, "high": 9.0},
                  "s": {"low": 4.0, "average": 7.0, "high": 12.0}}  # fmt: skip


@pytest.mark.parametrize(("inputs", "scale", "raises_alarm"), [
    ((30.0, 3.0, 4.0), 100.0, False), ((30.0, 6.0, 12.0), 70.0, True),
    ((120.0, 3.0, 4.0), 60.0, True), ((120.0, 9.0, 11.0), 20.0, True),
])  # fmt: skip
def test_worked_cases(inputs, scale, raises_alarm):
    got, _, _ = integrity_scale(*inputs)
    assert got == pytest.approx(scale)
    assert bool(alarm(got)) is raises_alarm


def test_every_rule_fires_on_its_own_input():
    th = [REPRESENTATIVE["theta"][t] for t, _, _, _ in RULES]
    d = [REPRESENTATIVE["d"][x] for _, x, _, _ in RULES]
    s = [REPRESENTATIVE["s"][x] for _, _, x, _ in RULES]
    scale, level, rule = integrity_scale(np.array(th), np.array(d), np.array(s))
    assert list(rule) == list(range(1, 19))
    assert list(scale) == list(SCORES)
    assert list(SCORES) == [100, 90, 90, 80, 80, 80, 70, 70, 60, 60, 50, 50, 40, 40, 40, 30, 30, 20]
    assert list(level[:3]) == ["very high"] * 3 and level[6] == "average" and level[17] == "low"
    # OK iff Δθ < 90° and the distance and speed weights add up to at least 40
    assert list(~alarm(scale)) == [True] * 6 + [False] * 12


def test_memberships_at_the_breakpoints():
    mu = memberships([89.999, 90.0], [4.0, 8.0], [5.0, 10.0])
    assert list(mu["theta"]["good"]) == [1.0, 0.0] and list(mu["theta"]["bad"]) == [0.0, 1.0]  # 90° is bad
    assert list(mu["d"]["low"]) == [1.0, 0.0] and list(mu["d"]["average"]) == [0.0, 1.0]  # 4 low, 8 average
    assert list(mu["s"]["low"]) == [1.0, 0.0] and list(mu["s"]["average"]) == [0.0, 1.0]  # 5 low, 10 average
    above = memberships(90.0, 8.001, 10.001)
    assert above["d"]["high"] == 1.0 and above["s"]["high"] == 1.0


def test_soft_memberships_sum_to_one_and_reduce_to_crisp():
    x = np.linspace(0.0, 20.0, 401)
    mu = memberships(np.full_like(x, 30.0), x, x, ramp=2.0)
    for group in ("d", "s"):
        total = sum(mu[group].values())
        assert np.allclose(total, 1.0)
    assert mu["d"]["low"][x == 4.0] == pytest.approx(0.5) and mu["d"]["average"][x == 4.0] == pytest.approx(0.5)
    soft, _, _ = integrity_scale(30.0, 6.0, 7.0, ramp=2.0)  # far from every breakpoint: the crisp answer
    assert soft == pytest.approx(80.0)
    mid, _, _ = integrity_scale(30.0, 4.0, 4.0, ramp=2.0)  # half low, half average distance: between 100 and 90
    assert mid == pytest.approx(95.0)


def test_undefined_inputs_give_no_scale_and_an_alarm():
    scale, level, rule = integrity_scale(np.nan, 3.0, 4.0)
    assert np.isnan(scale) and rule == 0 and level == "" and alarm(scale)
