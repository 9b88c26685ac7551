"""Known answers from the papers for the RAIM parameter derivations."""

import numpy as np
import pytest

from tollcli.integrity import design


def test_classic_k1_pmd_1e3_pfa_1e5_sqrt_lambda_det_7_5():
    # paper 001, Fig. 6 discussion: k = 1, P_MD = 1e-3, P_FA = 1e-5 ⇒ √λ_det ≈ 7.5
    assert np.sqrt(design.classic_lambda_det(1e-5, 1e-3, np.array([1]))[0]) == pytest.approx(7.5, abs=0.01)


@pytest.mark.parametrize(
    "k, th, sqrt_lam",
    [(1, 7.879, 6.698), (2, 10.597, 7.043), (3, 12.838, 7.280), (4, 14.860, 7.469), (5, 16.750, 7.629), (6, 18.548, 7.768)],
)
def test_classic_lookup_table_pfa_5e3_pmd_5e5(k, th, sqrt_lam):
    # notes-salos appendix: Th / √λ_det for P_FA 5e-3, P_MD 5e-5
    assert design.classic_threshold(5e-3, k) == pytest.approx(th, abs=5e-4)
    assert np.sqrt(design.classic_lambda_det(5e-3, 5e-5, np.array([k]))[0]) == pytest.approx(sqrt_lam, abs=5e-4)


def test_etc_hal_over_slope_7_gives_pfa_1e4():
    # paper 001 Fig. 6: k = 1, P_MD = 1e-3, HAL/slope_max = 7 ⇒ fault-free validated w.p. ≈ 1 − 1e-4
    th = design.etc_threshold(1e-3, 1, 49.0)
    assert design.false_alarm_probability(th, 1) == pytest.approx(9.24e-5, rel=1e-2)


@pytest.mark.parametrize("ratio, th, p_fa", [(6, 4.450, 3.49e-2), (7, 9.668, 1.88e-3), (8, 16.887, 3.97e-5)])
def test_etc_reference_values_pmd_5e5_k1(ratio, th, p_fa):
    got = design.etc_threshold(5e-5, 1, ratio**2)
    assert got == pytest.approx(th, abs=5e-4)
    assert design.false_alarm_probability(got, 1) == pytest.approx(p_fa, rel=1e-2)


@pytest.mark.parametrize("ratio, p_fa", [(6, 1.85e-1), (7, 2.02e-2), (8, 7.80e-4)])
def test_etc_reference_values_pmd_5e5_k4(ratio, p_fa):
    th = design.etc_threshold(5e-5, 4, ratio**2)
    assert design.false_alarm_probability(th, 4) == pytest.approx(p_fa, rel=1e-2)


@pytest.mark.parametrize(
    "share, error, expected", [(99, 1, 1e-4), (99, 0.1, 1e-5), (99, 0.01, 1e-6), (99.9, 1, 1e-5), (99.9, 0.1, 1e-6)]
)
def test_thesis_table_5_1(share, error, expected):
    assert design.p_mgor_max(share, error) == pytest.approx(expected, rel=0.03)


def test_p_fgor_10050_segments_gives_1e6():
    assert design.p_fgor_max(99, 10_050) == pytest.approx(1e-6, rel=1e-3)


@pytest.mark.parametrize("n_th, p_md", [(1, 5.27e-5), (2, 1.25e-3), (3, 4.29e-3), (4, 8.77e-3), (5, 1.43e-2)])
def test_thesis_table_5_2(n_th, p_md):
    assert design.p_md_for_overcharge(n_th) == pytest.approx(p_md, rel=0.01)


def test_threshold_table_is_on_the_safe_side():
    rng = np.random.default_rng(7)
    k = rng.integers(1, 12, 400)
    lam = rng.uniform(0.0, 900.0, 400)
    table = design.EtcThresholdTable(5e-5)
    approx = table(k, lam)
    exact = design.etc_threshold(5e-5, k, lam)
    assert (approx <= exact + 1e-9).all()  # never a threshold above the exact one
    assert np.max(exact - approx) < 0.7  # and close: one grid step of √λ
    on_grid = np.array([49.0, 64.0])
    assert table(np.array([1, 1]), on_grid) == pytest.approx(design.etc_threshold(5e-5, np.array([1, 1]), on_grid))


def test_threshold_table_covers_modern_receivers_up_to_k_64():
    """Phones and multi-GNSS receivers: k up to 64 and λ_det far above 1 600 (slopes ≪ HAL/40). Over √λ up to
    6 000 (beyond the grid: computed exactly) the table is never above the exact threshold and within 10 % of it
    wherever the exact one is at least 1 (below, a grid step of √λ is the bound); P_FA is that of the threshold."""
    rng = np.random.default_rng(64)
    k = np.repeat(np.arange(1, 65), 40)
    sqrt_lam = np.concatenate([rng.uniform(0.0, 40.0, 10), rng.uniform(40.0, 4_000.0, 28), rng.uniform(4_000.0, 6_000.0, 2)])
    lam = np.tile(sqrt_lam, 64) ** 2
    table = design.EtcThresholdTable(5e-5)
    approx, exact = table(k, lam), design.etc_threshold(5e-5, k, lam)
    assert (approx <= exact * (1 + 1e-12) + 1e-12).all()
    big = exact >= 1.0
    assert (approx[big] >= 0.9 * exact[big]).all(), np.min(approx[big] / exact[big])
    assert np.allclose(table.p_fa(k, lam), design.false_alarm_probability(approx, k), rtol=1e-9, equal_nan=True)
