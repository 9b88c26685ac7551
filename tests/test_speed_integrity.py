"""Speed integrity: the thesis's averages, the low-speed rule, and a speed fault on a simulated drive."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tollcli.integrity.speed import detrended_standard_error, speed_integrity, trapezoid_average
from tollcli.simulate.drive import SimConfig, simulate
from tollcli.simulate.route import straight


def test_trapezoid_average_known_answers():
    assert trapezoid_average(np.full(20, 0.3), 10)[10:] == pytest.approx(np.full(10, 0.3))  # constant SDOP s: MASE = s
    ramp = np.arange(20, dtype=float)
    assert trapezoid_average(ramp, 4)[4] == pytest.approx((0.5 * 0 + 1 + 2 + 3 + 0.5 * 4) / 4)
    assert np.isnan(trapezoid_average(ramp, 4)[:4]).all()


def test_detrended_standard_error_ignores_steady_acceleration():
    t = np.arange(50, dtype=float)
    assert detrended_standard_error(10 + 0.8 * t, 10)[10:] == pytest.approx(np.zeros(40), abs=1e-5)
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 0.2, 200_000)
    se = detrended_standard_error(noise, 10)[10:]
    assert np.sqrt(np.mean((se * np.sqrt(11)) ** 2)) == pytest.approx(0.2, rel=0.02)


def _drive(edit=None, seconds=300, speed_mps=13.89, rate_hz=1.0, stops=()):
    traj = straight(42.6, 2.88, 30.0, speed_mps, seconds, rate_hz, stops=list(stops))
    chunks = list(simulate(traj, SimConfig(env="rural", seed=8)))
    epochs = pd.concat([c.epochs for c in chunks], ignore_index=True)
    return edit(epochs) if edit else epochs


def test_a_clean_drive_passes_and_a_speed_fault_is_flagged():
    clean = speed_integrity(_drive())
    assert (clean["speed_status"][10:] == "ok").mean() > 0.85 and "inconsistent" not in set(clean["speed_status"])
    assert clean["speed_error_mps"].iloc[-1] == pytest.approx(0.1 / np.sqrt(10))

    def fault(epochs):  # the reported (Doppler) speed 4 m/s too high for 60 s
        sel = (epochs["t_s"] >= 120) & (epochs["t_s"] < 180)
        epochs.loc[sel, "speed_mps"] += 4.0
        return epochs

    flagged = speed_integrity(_drive(fault))["speed_status"].to_numpy()
    inside = flagged[135:180]
    assert (inside == "inconsistent").mean() > 0.9
    assert (flagged[200:] == "ok").mean() > 0.99


def test_low_speed_rule():
    """A vehicle slower than 2 m/s is not checked (low_speed), and is no fault; a 1 m/s speed reported while the
    positions move at 13.9 m/s is one."""
    slow = speed_integrity(_drive(speed_mps=1.0))
    assert set(slow["speed_status"][10:]) == {"low_speed"}
    wrong = speed_integrity(_drive(lambda e: e.assign(speed_mps=1.0)))
    assert set(wrong["speed_status"][10:]) == {"inconsistent"}
