"""The trajectory estimator (``--positioning``): the real Berlin city drive audited against its truth, the estimator's
pieces on known answers, and what an invoice records.

The Berlin figures are the tool's own (``tollcli integrity`` then ``tollcli audit --epochs --truth``), with the
default settings: the estimator never reads the truth.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import run_cli, shared

from tollcli.gnss.odometry import implausible_odometry, interval_odometry
from tollcli.integrity.trajectory import at_the_ends, inherited_at_the_ends, sigma_major_m
from tollcli.integrity.trajectory_noise import correlation_inflation, position_inflation, sigma_by_cn0

BERLIN = ("smartloc", "Berlin_Potsdamer_Platz_Input.txt")
TRUTH = ("smartloc", "Berlin_Potsdamer_Platz_GT.txt")


def _audited(tmp_path, log, *options: str) -> tuple[dict, dict]:
    """The integrity summary and the audit against the Berlin truth of one run of ``tollcli integrity``."""
    table = tmp_path / "epochs.csv"
    proc = run_cli("integrity", str(log), "-o", str(table), "--json", "-q", *options)
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    report = tmp_path / "audit.json"
    proc = run_cli("audit", "--epochs", str(table), "--truth", str(shared(*TRUTH)), "-o", str(report), "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    return summary, json.loads(report.read_text())["integrity"]


def test_berlin_smoothed_by_default_is_available_and_never_misleading(tmp_path):
    """Defaults on the real city drive: ≥ 95 % of epochs valid at HAL 50 m and ≥ 70 % at 30 m (the snapshot RAIM:
    0 %), no epoch misleading or hazardous, the error of the smoothed positions small."""
    log = shared(*BERLIN)
    valid = {}
    for hal, share in ((50, 0.95), (30, 0.70), (10, 0.0)):
        summary, audit = _audited(tmp_path, log, "--hal", str(hal))
        assert summary["positioning_used"] == "smoothed" and summary["integrity_sources"] == {"smoothed": 1372}
        assert summary["hal_m"] == hal
        valid[hal] = summary["statuses"].get("valid", 0)
        assert valid[hal] >= share * 1372
        assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0 and audit["undetected"] == 0
        if hal == 50:
            error = audit["horizontal_error_m"]
    assert valid[10] < valid[30] <= valid[50]  # the HAL is the one asked for
    assert error["median"] <= 8.0 and error["p95"] <= 15.0 and error["max"] <= 20.0  # snapshot WLS: 27 / 62 m


def test_berlin_filtered_forward_only(tmp_path):
    """Forward only (what an on-board unit could do, each position from the measurements up to its epoch): ≥ 80 % valid
    at HAL 50 m, none misleading or hazardous; its error larger than the smoothed one's (it cannot use the future)."""
    _, smoothed = _audited(tmp_path, shared(*BERLIN))
    summary, audit = _audited(tmp_path, shared(*BERLIN), "--positioning", "filtered")
    assert summary["positioning_used"] == "filtered" and summary["statuses"].get("valid", 0) >= 0.80 * 1372
    assert audit["horizontal_error_m"]["median"] > 1.2 * smoothed["horizontal_error_m"]["median"]
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0


@pytest.mark.parametrize(("part_s", "hal_m"), [((60, 190), 50), ((105, 235), 50), ((120, 250), 50), ((120, 250), 30)])
def test_parts_of_berlin_are_never_misleading(tmp_path, part_s, hal_m):
    """A part of the real drive is a real log (``benchmarks/berlin_cuts.py`` runs 29 of them). The first two, whose
    satellites' errors lean north together at 170–190 s, had 85 and 137 epochs beyond their bound while the noise was
    measured per satellite only (:func:`position_inflation`); the part that starts at 120 s starts inside a 65 s
    reflection and had 103 (44 hazardous at HAL 30 m in the 29 parts) while its young forward pass shared in the
    position at its start (:func:`at_the_ends`). None now, at HAL 50 m or 30 m."""
    start, end = part_s
    lines = shared(*BERLIN).read_text().splitlines(keepends=True)
    part = tmp_path / "part.txt"
    part.write_text("".join(line for line in lines if start <= float(line.split()[1]) <= end))
    summary, audit = _audited(tmp_path, part, "--hal", str(hal_m))
    assert summary["positioning_used"] == "smoothed"
    assert summary["statuses"].get("valid", 0) >= (0.9 if hal_m == 50 else 0.5) * audit["epochs"]
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0


def test_near_the_ends_the_older_pass_alone():
    """Within ``end_s`` of the log's first epoch the position and covariance are the backward pass's, within ``end_s``
    of its last the forward pass's, between them the combination; where an epoch is near both ends (a short log), the
    combination."""
    from types import SimpleNamespace

    n = 100
    t_s = np.arange(n, dtype=float)

    def states(value):
        return np.full((n, 5), value), np.broadcast_to(value * np.eye(2), (n, 2, 2)).copy()

    (x, cov), (xf, covf), (xb, covb) = states(1.0), states(2.0), states(3.0)
    passes = SimpleNamespace(x=x, cov_en_m2=cov, forward_x=xf, forward_cov_en_m2=covf, backward_x=xb, backward_cov_en_m2=covb)
    got_x, got_cov = at_the_ends(t_s, passes, 10.0)
    np.testing.assert_array_equal(got_x[:, 0], np.where(t_s < 10, 3.0, np.where(t_s > 89, 2.0, 1.0)))
    np.testing.assert_array_equal(got_cov[:, 1, 1], got_x[:, 0])
    assert (passes.x == 1.0).all()  # the sweep's own arrays are left as they were
    got_x, _ = at_the_ends(t_s, passes, 60.0)
    np.testing.assert_array_equal(got_x[:, 0], np.where(t_s < 40, 3.0, np.where(t_s > 59, 2.0, 1.0)))


def test_the_ends_inherit_the_fault_test_from_beyond_their_windows():
    """Each end's window (within ``end_s`` of the first or last epoch) takes the largest statistic of the ``beyond_s``
    seconds beyond it, and lost if an epoch there is; epochs farther in, and NaN statistics, give nothing."""
    t_s = np.arange(100, dtype=float)
    stat = np.ones(100)
    stat[[12, 25, 40, 80]] = [7.0, 50.0, 90.0, 30.0]  # 12: beyond the first window; 25: farther; 80: beyond the last
    stat[15] = np.nan
    lost = np.zeros(100, bool)
    lost[[5, 85]] = True  # inside the first window (its own), beyond the last
    got, got_lost = inherited_at_the_ends(t_s, stat, lost, 10.0, 10.0)
    want = stat.copy()
    want[:10], want[90:] = 7.0, 30.0
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got_lost, lost | (t_s >= 90))
    assert stat[0] == 1.0 and not lost[95]  # the inputs are left as they were
    got, _ = inherited_at_the_ends(t_s, np.full(100, np.nan), lost, 10.0, 10.0)
    assert np.isnan(got).all()
    got, got_lost = inherited_at_the_ends(t_s, stat, lost, 10.0, 1000.0)  # beyond: the whole of the log past the window
    assert (got[:10] == 90.0).all() and (got[90:] == 90.0).all() and got_lost[:10].all() and got_lost[90:].all()


def test_berlin_snapshot_is_todays(tmp_path):
    """``--positioning snapshot``: each epoch alone, judged by the RAIM: nothing valid in the canyon, nothing
    misleading either (the positioning the tool had before the estimator)."""
    summary, audit = _audited(tmp_path, shared(*BERLIN), "--positioning", "snapshot")
    assert summary["positioning_used"] == "snapshot" and "smoothed" not in summary["integrity_sources"]
    assert summary["statuses"].get("valid", 0) == 0
    assert audit["horizontal_error_m"]["median"] > 20


def test_interval_odometry_integrates_what_moved_between_epochs():
    """Known answer: a constant 10 m/s and 0.1 rad/s sampled at 5 Hz give exactly those over every interval between
    3 Hz epochs; an interval across a 2 s hole in the samples is unknown (NaN), and so is the first."""
    t = np.arange(0, 20, 0.2)
    keep = (t < 8) | (t > 10)
    speed, yaw = interval_odometry(t[keep], np.full(keep.sum(), 10.0), np.full(keep.sum(), 0.1), np.arange(0.1, 19, 1 / 3))
    epochs = np.arange(0.1, 19, 1 / 3)
    hole = (epochs > 7.8) & (epochs < 10.5)
    assert np.isnan(speed[0]) and np.isnan(speed[1:][hole[1:]]).all()
    ok = ~np.isnan(speed)
    assert ok.sum() > 40 and np.allclose(speed[ok], 10.0) and np.allclose(yaw[ok], 0.1)


def test_noise_per_cn0_bin_and_its_correlation():
    """Properties: white residuals give a correlation factor near 1; the same residuals held for 20 epochs each
    (a reflection that lasts) give about 20 (the variance of a mean of 20 equal errors is 20× a white mean's);
    σ per C/N0 bin is the bin's spread with its bias, and a bin with too few residuals takes the largest."""
    rng = np.random.default_rng(4)
    n_epochs, n_sats = 4000, 8
    white = rng.normal(size=(n_epochs, n_sats))
    sv = np.tile(np.array([f"G{k:02d}" for k in range(n_sats)], dtype=object), (n_epochs, 1))
    mask = np.ones(white.shape, bool)
    factor, _ = correlation_inflation(white, sv, mask)
    assert 0.8 < factor < 1.3
    held = np.repeat(rng.normal(size=(n_epochs // 20, n_sats)), 20, axis=0)
    factor, rho = correlation_inflation(held, sv, mask)
    assert 15 < factor < 25 and rho[10] > 0.4
    codes = pd.factorize(sv.ravel(), sort=True)[0].reshape(sv.shape)  # the labels as the estimator passes them
    assert correlation_inflation(held, codes, mask)[0] == factor
    cn0 = np.where(np.arange(n_sats) < 4, 42.0, 27.0)[None, :].repeat(n_epochs, 0)
    cn0[0, 0] = 10.0  # one lonely residual below 25 dB-Hz
    residual = np.where(cn0 > 40, 2.0 * white, 30.0 + 10.0 * white)
    table = sigma_by_cn0(residual, cn0, mask)
    assert table[4] == pytest.approx(3.0, abs=0.3)  # 40–45 dB-Hz: σ 2 m, floored at 3 m
    assert table[1] == pytest.approx(np.hypot(30.0, 10.0), rel=0.05)  # 25–30 dB-Hz: bias and spread
    assert table[0] == table.max()


def test_errors_leaning_together_inflate_the_noise_as_the_position_sees_them():
    """Known answer: every satellite's error the projection of one east offset c (unit variance, held 20 epochs)
    plus white noise. Each satellite alone sees a little of c; the position sees all of it: its east series
    δ / √Q_EE = c √s + white (s = 1 / Q_EE) has mean square 1 + s and ρ(lag) = (1 − lag/20) s / (1 + s), so the
    factor is (1 + s)(1 + 19 s / (1 + s)) = 1 + 20 s. White errors alone give 1. An epoch with no more measurements
    than unknowns + 1 tells nothing (its offset would be its residuals' fit)."""
    from types import SimpleNamespace

    rng = np.random.default_rng(7)
    n_epochs, n_sats = 8000, 9
    az = np.radians(np.arange(n_sats) * 40.0 + 5.0)
    el = np.radians(np.array([15, 25, 35, 45, 55, 65, 75, 30, 50], float))
    unit = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)  # ENU, to the satellites
    inp = SimpleNamespace(origin_ecef_m=np.zeros(3), ecef2enu=np.eye(3), n_clocks=2,
                          sat_ecef_m=np.broadcast_to(2.0e7 * unit, (n_epochs, n_sats, 3)),
                          clock_index=np.broadcast_to((np.arange(n_sats) >= 6).astype(int), (n_epochs, n_sats)))  # fmt: skip
    x = np.zeros((n_epochs, 9))
    mask = np.ones((n_epochs, n_sats), bool)
    white = rng.normal(size=(n_epochs, n_sats))
    factor, _ = position_inflation(white, inp, x, mask)
    assert 0.85 < factor < 1.2
    h = np.column_stack([-unit, np.arange(n_sats) < 6, np.arange(n_sats) >= 6])
    s = 1.0 / np.linalg.inv(h.T @ h)[0, 0]
    c = np.repeat(rng.normal(size=n_epochs // 20), 20)
    leaning = white + c[:, None] * -unit[None, :, 0]  # a range error of −u_E c: the position c east
    factor, rho = position_inflation(leaning, inp, x, mask)
    assert factor == pytest.approx(1.0 + 20.0 * s, rel=0.15) and rho[10] > 0.2
    assert factor > 3 * correlation_inflation(leaning, np.tile(np.arange(n_sats), (n_epochs, 1)), mask)[0]
    few = mask.copy()
    few[:, 1:4] = False  # 6 measurements, 3 + 2 clocks unknowns: no offset anywhere
    assert position_inflation(leaning, inp, x, few) == (1.0, pytest.approx(np.ones(1)))


def test_the_offsets_are_each_epochs_least_squares():
    """The offsets :func:`position_inflation` solves (clocks taken out by their groups' means, a 3 × 3 system in
    closed form) are each epoch's least squares with a column per clock group, solved directly, over random
    geometries with slots missing and a constellation absent at some epochs; too few measurements give none."""
    from types import SimpleNamespace

    from tollcli.integrity.trajectory_noise import _offsets

    rng = np.random.default_rng(3)
    n_epochs, n_sats, n_clocks = 300, 12, 3
    sat = rng.normal(size=(n_epochs, n_sats, 3))
    sat[..., 2] = np.abs(sat[..., 2]) + 0.2
    sat *= 2.0e7 / np.linalg.norm(sat, axis=-1, keepdims=True)
    inp = SimpleNamespace(origin_ecef_m=np.array([1.0e6, -2.0e6, 3.0e6]), ecef2enu=np.linalg.qr(rng.normal(size=(3, 3)))[0].T)
    enu = rng.normal(scale=50.0, size=(n_epochs, 3))
    clock = rng.integers(0, n_clocks, size=(n_epochs, n_sats))
    clock[::4] = np.where(clock[::4] == 2, 1, clock[::4])  # no third constellation at every fourth epoch
    mask = rng.random((n_epochs, n_sats)) < 0.7
    z = np.where(mask, rng.normal(size=(n_epochs, n_sats)), np.nan)
    got = _offsets(z, mask, sat @ inp.ecef2enu + inp.origin_ecef_m, clock, enu, inp, n_clocks)
    for k in range(n_epochs):
        ok = mask[k]
        los = sat[k, ok] - enu[k]  # ENU (the frame's rotation undone above)
        unit = los / np.linalg.norm(los, axis=1, keepdims=True)
        groups = np.unique(clock[k, ok])
        h = np.column_stack([-unit] + [clock[k, ok] == g for g in groups]).astype(float)
        if ok.sum() < h.shape[1] + 2:
            assert np.isnan(got[k]).all()
            continue
        q = np.linalg.inv(h.T @ h)
        delta = q @ h.T @ z[k, ok]
        np.testing.assert_allclose(got[k], delta[:2] / np.sqrt(np.diag(q)[:2]), rtol=1e-9, atol=1e-9)


def test_sigma_major_is_the_ellipse_semi_major_axis():
    """Known answers: a diagonal covariance's larger σ; a rotated one's."""
    angle = np.radians(30.0)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cov = np.stack([np.diag([9.0, 4.0]), rot @ np.diag([25.0, 1.0]) @ rot.T])
    assert np.allclose(sigma_major_m(cov), [3.0, 5.0])


def test_the_invoice_says_which_positioning_and_verify_reproduces_it(tmp_path):
    """``process`` of the Berlin drive with roads laid along its snapshot track: by default the smoothed trajectory
    charges (``parameters.positioning``/``positioning_used``), its evidence positions a correlation time apart
    (``tc_used_s``), ``verify`` reproduces the invoice from its recorded settings, and ``--positioning snapshot``
    charges nothing there (each epoch alone is unavailable) and records the settings as invoices did before (an
    invoice made before the estimator verifies)."""
    import pandas as pd

    from conftest import BERLIN_START, REPO, roads_along_the_berlin_drive

    log = str(shared(*BERLIN))
    geo = roads_along_the_berlin_drive(tmp_path)
    tariff = str(REPO / "geoobjects" / "example-tariff.toml")
    invoices = {}
    for positioning in ("smoothed", "snapshot"):
        out = tmp_path / f"{positioning}.json"
        extra = () if positioning == "smoothed" else ("--positioning", positioning)
        proc = run_cli("process", log, "--geo", str(geo), "--tariff", tariff, "-o", str(out), "-q", "--start-time", BERLIN_START, *extra)
        assert proc.returncode == 0, proc.stderr.decode()
        invoices[positioning] = json.loads(out.read_text())
    assert invoices["smoothed"]["parameters"]["positioning"] == "auto"  # the default: smoothed, the log has odometry
    assert invoices["smoothed"]["parameters"]["positioning_used"] == "smoothed"
    assert "positioning" not in invoices["snapshot"]["parameters"]  # snapshot positions: recorded as before the estimator
    assert invoices["smoothed"]["lines"] and not invoices["snapshot"]["lines"]
    # smoothed positions' errors stay correlated for tens of seconds (the residuals' ρ): evidence counts that far apart
    tc_used = invoices["smoothed"]["parameters"]["tc_used_s"]
    assert 10.0 < tc_used < 120.0 and "tc_used_s" not in invoices["snapshot"]["parameters"]
    for line in invoices["smoothed"]["lines"]:
        times = sorted(pd.Timestamp(e["time_utc"]) for e in line["evidence"])
        assert all((b - a).total_seconds() >= tc_used for a, b in zip(times, times[1:]))
        assert line["n_valid_independent"] <= 1 + line["n_valid"] // 10
    for positioning in ("smoothed", "snapshot"):
        proc = run_cli("verify", str(tmp_path / f"{positioning}.json"))
        assert proc.returncode == 0, proc.stderr.decode()


def test_without_odometry_auto_smooths_with_the_gnss_only_model(tmp_path):
    """The Berlin drive without its ``odom3`` lines: ``auto`` (the default) runs the GNSS-only motion model; nothing it
    declares valid is misleading or hazardous, and it vouches for at least 40 % of the drive at HAL 50 m (45.5 % when
    written) where the snapshot RAIM vouches for none; its positions are better than the snapshot WLS's."""
    log = tmp_path / "berlin-no-odometry.txt"
    log.write_text("".join(line for line in shared(*BERLIN).read_text().splitlines(keepends=True) if not line.startswith("odom3")))
    summary, audit = _audited(tmp_path, log)
    assert summary["positioning"] == "auto" and summary["positioning_used"] == "smoothed"
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0 and audit["undetected"] == 0
    assert summary["statuses"].get("valid", 0) >= 0.4 * 1372
    assert audit["horizontal_error_m"]["median"] < 16.0 and audit["horizontal_error_m"]["max"] < 45.0  # snapshot: 27.8 / 79 m
    summary, _ = _audited(tmp_path, log, "--positioning", "snapshot")
    assert summary["statuses"].get("valid", 0) == 0


def test_a_simulated_city_drive_with_a_satellite_fault(tmp_path):
    """``tollcli simulate --nlos --odometry`` (city reflections, wheel speed and gyro with their errors), 3 000 epochs
    with a 100 m bias on one satellite for 60 s: the smoothed trajectory declares none misleading, sets the faulty
    measurement aside while it lasts (the robust loss, ``excluded_sv`` ``set_aside:N``), and vouches for most of the
    drive."""
    import pandas as pd

    proc = run_cli("simulate", "--nlos", "--odometry", "--duration", "600", "--rate", "5", "--seed", "12", "--fault-at", "300",
                   "--fault-bias", "100", "--fault-duration", "60", "-o", str(tmp_path), "-q")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    table = tmp_path / "epochs.csv"
    proc = run_cli("integrity", str(tmp_path / "drive-librsf.txt"), "-o", str(table), "--json", "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert summary["positioning_used"] == "smoothed" and summary["epochs"] == 3000
    assert summary["statuses"].get("valid", 0) >= 0.6 * 3000
    report = tmp_path / "audit.json"
    proc = run_cli("audit", "--epochs", str(table), "--truth", str(tmp_path / "truth-librsf.txt"), "-o", str(report), "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    audit = json.loads(report.read_text())["integrity"]
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0
    epochs = pd.read_csv(table)
    t = (pd.to_datetime(epochs["time_utc"]) - pd.to_datetime(epochs["time_utc"]).iloc[0]).dt.total_seconds()
    set_aside = epochs["excluded_sv"].fillna("").str.startswith("set_aside:")
    during = t.between(300, 359.9)
    # the robust loss caught the fault (at the other fault epochs the faulty satellite was below the C/N0 mask: not used)
    assert set_aside[during].mean() > 0.85 and set_aside[~during].mean() < 0.2
    alarms = t[epochs["raim_status"] == "fault_detected"]
    assert alarms.between(300 - 250, 360 + 250).all()  # an alarm, if any, near the fault


def test_odometry_the_fixes_contradict_is_found():
    """Known answer: a car driving 10 m/s east for 200 s (fixes 20 m scattered), its odometer reading 0 from 80 s to
    140 s: the intervals around the stuck minute are marked, the rest not; a correct odometer marks nothing, nor does
    one reading 10 % too much (a straight line shorter than the road is no contradiction)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 200.0, 0.5)
    fixes = np.stack([10.0 * t, np.zeros(t.size)], axis=1) + rng.normal(0, 20, (t.size, 2))
    forward = np.full(t.size, 5.0)
    forward[0] = np.nan
    assert not implausible_odometry(t, fixes, forward).any()
    assert not implausible_odometry(t, fixes, 1.1 * forward).any()
    stuck = np.where((t > 80) & (t <= 140), 0.0, forward)
    bad = implausible_odometry(t, fixes, stuck)
    assert bad[(t > 85) & (t <= 135)].all() and not bad[(t < 30) | (t > 190)].any()


@pytest.fixture(scope="module")
def walk():
    """rtklibexplorer's u-blox walk solved once: its epoch table and measurements."""
    from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
    from tollcli.gnss.sigma_models import NominalModel

    return pseudorange_epochs(str(shared("rtklibexplorer", "gnss_1730.ubx")), "ubx", None, "nominal", 5.0, NominalModel())


def test_a_receiver_clock_drifting_60_mps_does_not_start_a_pass_lost(walk):
    """rtklibexplorer's u-blox walk (open sky, its TCXO drifting −60 m/s): smoothed, every epoch valid. With the
    drift's start σ at 10 m/s the backward pass's first clocks ran off their prior, the pass "lost the vehicle" at
    its second epoch and the 30 s around it (123 epochs) were fault_detected; a 1 ppm TCXO (300 m/s) is allowed
    for now."""
    from tollcli.integrity.trajectory import with_trajectory

    epochs, meas = walk
    assert np.nanmedian(epochs["clock_drift_mps"]) < -50.0  # the receiver's own Doppler says so
    placed, meas, used = with_trajectory(epochs, meas, "smoothed")
    assert used == "smoothed" and not meas.trajectory_lost.any()
    assert np.nanmax(meas.trajectory_hpl_m) < 20.0


def test_the_walks_bounds_hold_against_its_rtk_reference(walk):
    """rtklibexplorer's triple-band u-blox walk against the receiver's own RTK solution (``gnss_1730_sf.pos``): the
    snapshot and the smoothed positions lie 8–9 m from it, and every epoch's HPL still covers that. Most of it is the
    reference's own offset, not the positions' error: RTKLIB's single-point solutions of the log (``convbin``, then
    ``rnx2rtkp``, GPS L1+L2) lie 8.5 m from it with the broadcast ionosphere and 8.2 m with the dual-frequency
    ionosphere-free combination, both 7.4 m east and 19–25 m below it — an RTK solution is relative to its base, whose
    coordinates were not absolute. So the walk checks a bound only against a reference that errs by metres; the
    Doppler in the filter tightened the smoothed HPL to 3.8 m here, which this reference cannot vouch for either way,
    and the broadcast ionosphere's error (3.7 m north, 5.5 m up between RTKLIB's two solutions), common to every
    satellite, is one a Doppler-tightened bound would not cover: not adopted."""
    from tollcli.geodesy import enu_rotation, geodetic2ecef
    from tollcli.integrity.raim import RaimParams
    from tollcli.integrity.run import run_raim
    from tollcli.integrity.trajectory import with_trajectory

    pos = pd.read_csv(shared("rtklibexplorer", "gnss_1730_sf.pos"), comment="%", sep=r"\s+", header=None)
    truth = pd.DataFrame({"lat": pos[2].to_numpy(), "lon": pos[3].to_numpy(), "h": pos[4].to_numpy()},
                         index=pd.to_datetime(pos[0] + " " + pos[1]))  # GPS time  # fmt: skip
    epochs, meas = walk
    when = pd.to_datetime(epochs["time_utc"]).dt.tz_localize(None) + pd.Timedelta(seconds=18)
    ref = truth.reindex(when, method="nearest", tolerance=pd.Timedelta("0.1s"))
    assert ref["lat"].notna().all()
    rot = np.asarray(enu_rotation(float(ref["lat"].iloc[0]), float(ref["lon"].iloc[0])), float).reshape(3, 3)
    at = np.stack(geodetic2ecef(ref["lat"], ref["lon"], ref["h"]), -1)

    def horizontal(table) -> np.ndarray:
        d = (np.stack(geodetic2ecef(table["lat_deg"], table["lon_deg"], table["height_m"]), -1) - at) @ rot.T
        return np.hypot(d[:, 0], d[:, 1])

    snapshot = run_raim(meas, RaimParams("ss"))
    error = horizontal(epochs)
    assert 6.0 < np.median(error) < 11.0
    assert (error < snapshot["hpl_m"].to_numpy(float)).all()
    placed, smoothed, used = with_trajectory(epochs, meas, "smoothed")
    assert used == "smoothed"
    assert (horizontal(placed) < smoothed.trajectory_hpl_m).all()


def test_pseudoranges_below_the_cn0_mask_change_nothing():
    """Metamorphic: a pseudorange received below the C/N0 mask (30 dB-Hz) is left out of the trajectory — moving
    every one of them 500 m gives the same trajectory to the last bit, while with no mask it moves the positions;
    a C/N0 not reported keeps its measurement (the weak ones' C/N0 blanked, the move counts again)."""
    from dataclasses import replace

    from tollcli.gnss.librsf_positions import librsf_epochs
    from tollcli.integrity.trajectory import MIN_CN0_DBHZ, estimate_trajectory
    from tollcli.integrity.trajectory_inputs import trajectory_inputs
    from tollcli.readers.librsf import read_librsf

    epochs, meas = librsf_epochs(read_librsf(str(shared(*BERLIN))))
    inp = trajectory_inputs(epochs, meas)
    n = 400  # the first two minutes and more
    inp = replace(inp, **{f: getattr(inp, f)[:n] for f in ("t_s", "sat_ecef_m", "pr_m", "mask", "cn0_dbhz", "sigma_m",
                                                            "clock_index", "sv", "fix_enu_m", "speed_mps", "yaw_rate_radps",
                                                            "forward_m", "left_m")})  # fmt: skip
    weak = inp.mask & (inp.cn0_dbhz < MIN_CN0_DBHZ)
    assert 0.05 < weak.sum() / inp.mask.sum() < 0.5
    moved = replace(inp, pr_m=np.where(weak, inp.pr_m + 500.0, inp.pr_m))
    base = estimate_trajectory(inp)
    same = estimate_trajectory(moved)
    np.testing.assert_array_equal(same.enu_m, base.enu_m)
    np.testing.assert_array_equal(same.hpl_m, base.hpl_m)
    unmasked = np.abs(estimate_trajectory(moved, min_cn0_dbhz=0.0).enu_m - estimate_trajectory(inp, min_cn0_dbhz=0.0).enu_m)
    assert unmasked.max() > 0.1
    blank = np.where(weak, np.nan, inp.cn0_dbhz)
    unreported = np.abs(estimate_trajectory(replace(moved, cn0_dbhz=blank)).enu_m - estimate_trajectory(replace(inp, cn0_dbhz=blank)).enu_m)
    assert unreported.max() > 0.1
