"""Integrity sources (integrity/sources.py): GBS and GST verdicts, the strictest wins, levels, the invoice's record."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from test_integrity_inputs import _epoch_with_grs

from tollcli.gnss.nmea_measurements import nmea_measurements
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim, settle_sources
from tollcli.integrity.sources import LEVELS, k_h
from tollcli.readers.nmea import compose, read_nmea


def _gbs(tod: float, err_lat="1.0", err_lon="1.0", failed="", bias="", sd=""):
    return compose.with_checksum(f"GNGBS,{compose.hhmmss(tod)},{err_lat},{err_lon},2.0,{failed},,{bias},{sd},1,1")


def _raim(lines, **params):
    tables = read_nmea(io.BytesIO(("\n".join(lines) + "\n").encode()))
    return run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc", **params))


def test_k_h_is_the_2d_gaussian_radius():
    assert k_h(5e-5) == pytest.approx(math.sqrt(-2 * math.log(5e-5))) == pytest.approx(4.4505, abs=1e-4)
    # P(|x| > K_H σ) for a circular 2-D Gaussian is exp(−K_H²/2) = P_MD
    rng = np.random.default_rng(1)
    r = np.hypot(*rng.standard_normal((2, 2_000_000)))
    assert np.mean(r > k_h(1e-3)) == pytest.approx(1e-3, rel=0.1)


def test_gbs_sigmas_of_1_m_at_p_md_5e_5_give_hpl_4_45_m_and_validate_below_the_hal():
    line = compose.gga(100.0, 42.7, 2.9, n_used=6)
    out = _raim([line, _gbs(100.0)], hal_m=50.0)
    assert out["hpl_gbs_m"].iloc[0] == pytest.approx(4.45, abs=0.005)
    assert out["raim_status"].iloc[0] == "valid" and out["integrity_source"].iloc[0] == "gbs"
    tight = _raim([line, _gbs(100.0)], hal_m=4.0)  # HPL 4.45 m > HAL 4 m
    assert tight["raim_status"].iloc[0] == "unavailable" and tight["gbs_status"].iloc[0] == "unavailable"
    wide = _raim([line, _gbs(100.0, err_lat="0.5", err_lon="3.0")], hal_m=50.0)  # σ_major = the larger σ
    assert wide["hpl_gbs_m"].iloc[0] == pytest.approx(k_h(5e-5) * 3.0)


@pytest.mark.parametrize("level", ["auto", "receiver", "covariance"])
def test_a_gbs_naming_a_failed_satellite_never_gives_a_valid_position(level):
    lines = []
    for k in range(4):
        tod = 100.0 + k
        lines += _epoch_with_grs(tod, [0.1, -0.2, 0.1, 0.05, -0.1, 0.2])  # a passing residual test
        lines.append(_gbs(tod, failed="07" if k % 2 else "", bias="12.6", sd="2.0"))
    out = _raim(lines, sources=None if level == "auto" else LEVELS[level])
    assert out["residual_status"].tolist() == ["valid"] * 4  # the residual test alone would pass them
    assert out["raim_status"].tolist() == ["valid", "fault_detected", "valid", "fault_detected"]
    assert out["integrity_source"].tolist() == ["grs", "gbs", "grs", "gbs"]


def test_a_grs_residual_test_that_says_fault_wins_over_gst_and_gbs():
    lines = []
    for k in range(3):
        tod = 100.0 + k
        lines += _epoch_with_grs(tod, [40.0, -35.0, 0.1, 0.05, -0.1, 0.2] if k == 1 else [0.1, -0.2, 0.1, 0.05, -0.1, 0.2])
        lines.append(_gbs(tod))
        lines.append(compose.gst(tod, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 2.0))
    for level in ("residual", "receiver", "covariance"):
        out = _raim(lines, sources=LEVELS[level])
        assert out["gbs_status"].tolist() == ["valid"] * 3 and out["gst_status"].tolist()[1] in ("valid", "fault_detected")
        assert out["raim_status"].iloc[1] in ("fault_detected", "probable_false_alarm") and out["integrity_source"].iloc[1] == "grs"
        assert out["raim_status"].iloc[0] == "valid"


def test_a_source_outside_the_level_cannot_validate_but_its_denials_count():
    line = compose.gga(100.0, 42.7, 2.9, n_used=6)
    ok = _raim([line, _gbs(100.0)], sources=LEVELS["residual"])
    assert ok["gbs_status"].iloc[0] == "valid" and ok["raim_status"].iloc[0] == "unmonitored"
    failed = _raim([line, _gbs(100.0, failed="12")], sources=LEVELS["residual"])
    assert failed["raim_status"].iloc[0] == "fault_detected" and failed["integrity_source"].iloc[0] == "gbs"


def test_auto_settles_on_the_strictest_level_of_the_first_epoch_with_a_source():
    def meas(lines):
        tables = read_nmea(io.BytesIO(("\n".join(lines) + "\n").encode()))
        return nmea_measurements(tables.epochs, tables.satellites)

    plain = [compose.gga(99.0, 42.7, 2.9, n_used=6)]
    with_gbs = plain + [compose.gga(100.0, 42.7, 2.9, n_used=6), _gbs(100.0)]
    assert settle_sources(RaimParams(), meas(plain)).sources == LEVELS["model"]  # GGA only: its HDOP, the model level
    partial = plain + _epoch_with_grs(100.0, [0.1] * 6)  # a first epoch cut short, then the receiver's whole epochs
    assert settle_sources(RaimParams(), meas(partial)).sources == LEVELS["residual"]
    assert settle_sources(RaimParams(), meas(with_gbs)).sources == LEVELS["receiver"]
    with_grs = _epoch_with_grs(100.0, [0.1] * 6) + [_gbs(100.0)]
    assert settle_sources(RaimParams(), meas(with_grs)).sources == LEVELS["residual"]
    gst_only = plain + [compose.gga(100.0, 42.7, 2.9, n_used=6), compose.gst(100.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 2.0)]
    assert settle_sources(RaimParams(), meas(gst_only)).sources == LEVELS["covariance"]
    satellites_only = [line for line in compose.straight_drive(2) if line[3:6] in ("GGA", "RMC", "GSA", "GSV")]
    assert settle_sources(RaimParams(), meas(satellites_only)).sources == LEVELS["model"]


def test_a_gbs_names_a_fault_only_when_its_bias_is_significant():
    """Read as the receiver meant it: GBS names its *most likely* failed satellite whatever the bias. 1.5 σ → no
    fault (its bound decides); 10 σ → fault; a missed-detection probability ≤ p_fa → fault; a satellite named with
    no figures → fault; a 3-satellite 2-D fix (no redundancy) → no GBS verdict at all."""
    import pandas as pd

    from tollcli.gnss.receiver_outputs import receiver_outputs
    from tollcli.integrity.raim import FAULT, VALID
    from tollcli.integrity.sources import NONE, receiver_verdicts

    epochs = pd.DataFrame({
        "gbs_err_lat_m": [2.0] * 6, "gbs_err_lon_m": [3.0] * 6, "gbs_failed_svid": [-1, 8, 8, 8, 8, 8],
        "gbs_bias_m": [np.nan, 1.5, 10.0, 1.0, np.nan, 0.0], "gbs_bias_sd_m": [np.nan, 1.0, 1.0, 1.0, np.nan, 0.0],
        "gbs_p_md": [np.nan, np.nan, np.nan, 1e-4, np.nan, np.nan],
        "n_used": [9, 9, 9, 9, 9, 3], "fix_mode": [3, 3, 3, 3, 3, 2],
    })  # fmt: skip
    verdict = receiver_verdicts(receiver_outputs(epochs), np.full(6, 50.0), 5e-5, p_fa=5e-3)["gbs"]
    assert verdict.tolist() == [VALID, VALID, FAULT, FAULT, FAULT, NONE]


def test_the_zed_f9t_insignificant_gbs_bias_is_no_longer_a_fault():
    """ublox-zed-f9t-ubx_nmea_l5.log: at 19:33:42 the receiver names satellite 8 with a 12.6 m bias of σ 219.6 m
    (0.06 σ): the epoch was fault_detected; it is the receiver's bound's now."""
    import io

    import pandas as pd
    from conftest import run_cli, shared

    # its NMEA (GBS, GST); read as it is recognised, its UBX NAV-SAT prRes decide at the residual level instead
    proc = run_cli("integrity", str(shared("gpsd", "ublox-zed-f9t-ubx_nmea_l5.log")), "-q", "--format", "nmea")
    table = pd.read_csv(io.BytesIO(proc.stdout))
    named = table["gbs_failed_svid"] == 8
    assert named.sum() == 1 and (table.loc[named, "gbs_status"] != "fault_detected").all()
    assert "fault_detected" not in set(table["raim_status"])
