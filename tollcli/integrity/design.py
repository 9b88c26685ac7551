"""RAIM and charging parameter derivations (paper 001 eqs. 16–24; thesis eqs. 5.5, 5.10).

Pure functions of probabilities and degrees of freedom ``dof`` (k = N_s − N_u);
they broadcast over numpy arrays. Thresholds apply to the WSSE test statistic
t = rᵀΣ⁻¹r, which is χ²_k without a fault and χ²_{k,λ} with one bias.

* classic WLSR RAIM: Th from P_FA, then λ_det such that P_MD = CDF_χ²_{k,λ_det}(Th);
  HPL = slope_max·√λ_det.
* ETC RAIM (HPL = HAL): λ_det = (HAL/slope_max)², Th = CDF⁻¹_χ²_{k,λ_det}(P_MD),
  and the resulting P_FA = 1 − CDF_χ²_k(Th) is reported per epoch.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


def _special():
    """scipy.special, imported when first needed (0.1 s): ``process`` with cached threshold rows never needs it."""
    from scipy import special

    return special


def classic_threshold(p_fa: float, dof) -> np.ndarray:
    """Th with P(t > Th) = p_fa for t ~ χ²_dof (NaN where dof < 1)."""
    dof = np.asarray(dof, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(dof >= 1, _special().chdtri(np.maximum(dof, 1), p_fa), np.nan)  # = stats.chi2.isf


@lru_cache(maxsize=4096)
def _lambda_det_scalar(p_fa: float, p_md: float, dof: int) -> float:
    from scipy import optimize

    special = _special()
    th = float(special.chdtri(dof, p_fa))

    def miss(lam: float) -> float:
        return float(special.chndtr(th, dof, lam)) - p_md

    hi = 10.0
    while miss(hi) > 0:
        hi *= 2.0
    return float(optimize.brentq(miss, 0.0, hi, xtol=1e-12, rtol=1e-12))


def classic_lambda_det(p_fa: float, p_md: float, dof) -> np.ndarray:
    """λ_det of the classic RAIM: P_MD = CDF_χ²_{k,λ_det}(Th(P_FA)) (NaN where dof < 1)."""
    dof = np.asarray(dof)
    out = np.full(dof.shape, np.nan)
    for k in np.unique(dof[dof >= 1]).astype(int):
        out[dof == k] = _lambda_det_scalar(float(p_fa), float(p_md), int(k))
    return out


def etc_threshold(p_md: float, dof, lambda_det) -> np.ndarray:
    """Exact ETC threshold Th = CDF⁻¹_χ²_{k,λ_det}(P_MD) (NaN where dof < 1 or λ not finite)."""
    dof = np.asarray(dof, dtype=float)
    lam = np.asarray(lambda_det, dtype=float)
    ok = (dof >= 1) & np.isfinite(lam)
    from scipy import stats

    with np.errstate(invalid="ignore"):
        th = stats.ncx2.ppf(p_md, np.where(ok, dof, 1), np.where(ok, np.maximum(lam, 1e-12), 1.0))
    return np.where(ok, th, np.nan)


class EtcThresholdTable:
    """Look-up table of ETC thresholds over (k, √λ_det), rounded on the safe side.

    Th grows with λ_det, so the table returns the threshold at the grid point
    just *below* √λ_det: never above the exact threshold (P_MD is kept; P_FA is
    a little higher than exact and is reported from the threshold used).
    The grid is uniform (``step``) up to ``sqrt_lambda_max``, then geometric (each point
    ``ratio`` times the last) up to ``sqrt_lambda_top``: good geometry with many satellites
    (slope ≪ HAL/40) has λ_det far above 1 600, where Th ≈ (√λ − z)² and a 1 % step in √λ
    costs ~2 % of Th. Above the grid the exact threshold is computed (rare: slope < HAL/4000).
    Rows for each k are computed on first use and kept in the cache directory.
    """

    def __init__(self, p_md: float, step: float = 0.01, sqrt_lambda_max: float = 40.0, ratio: float = 1.01,
                 sqrt_lambda_top: float = 4000.0):  # fmt: skip
        self.p_md = float(p_md)
        self.step = float(step)
        uniform = np.arange(0.0, sqrt_lambda_max + step / 2, step)
        n_geo = int(np.ceil(np.log(sqrt_lambda_top / uniform[-1]) / np.log(ratio)))
        self.grid = np.concatenate([uniform, uniform[-1] * ratio ** np.arange(1, n_geo + 1)])
        self.scheme = f"u{step!r}x{ratio!r}"
        self._rows: dict[int, np.ndarray] = {}
        self._p_fa_rows: dict[int, np.ndarray] = {}

    def _row(self, k: int) -> np.ndarray:
        row = self._rows.get(k)
        if row is None:
            row = _stored_row(self.p_md, self.scheme, self.grid, k)
            self._rows[k] = row
        return row

    def _p_fa_row(self, k: int) -> np.ndarray:
        row = self._p_fa_rows.get(k)
        if row is None:
            row = _stored_row(self.p_md, self.scheme, self.grid, k, what="pfa")
            self._p_fa_rows[k] = row
        return row

    def _lookup(self, dof, lambda_det, row_of, exact) -> np.ndarray:
        dof = np.asarray(dof)
        lam = np.asarray(lambda_det, dtype=float)
        out = np.full(np.broadcast(dof, lam).shape, np.nan)
        dof, lam = np.broadcast_arrays(dof, lam)
        ok = (dof >= 1) & np.isfinite(lam) & (lam >= 0)
        idx = np.zeros(out.shape, dtype=np.int64)
        with np.errstate(invalid="ignore"):
            idx[ok] = np.searchsorted(self.grid, np.sqrt(lam[ok]), side="right") - 1  # the grid point at or below
        above = ok & (idx >= self.grid.size - 1) & (lam > self.grid[-1] ** 2)
        table = ok & ~above
        for k in np.unique(dof[table]).astype(int):
            sel = table & (dof == k)
            out[sel] = row_of(int(k))[idx[sel]]
        if above.any():
            out[above] = exact(dof[above], lam[above])
        return out

    def __call__(self, dof, lambda_det) -> np.ndarray:
        """The threshold for each (k, λ_det)."""
        return self._lookup(dof, lambda_det, self._row, lambda k, lam: etc_threshold(self.p_md, k, lam))

    def p_fa(self, dof, lambda_det) -> np.ndarray:
        """P_FA of the threshold :meth:`__call__` gives: ``false_alarm_probability(self(dof, λ), dof)``, stored per row."""
        return self._lookup(dof, lambda_det, self._p_fa_row,
                            lambda k, lam: false_alarm_probability(etc_threshold(self.p_md, k, lam), k))  # fmt: skip


def _stored_row(p_md: float, scheme: str, grid: np.ndarray, k: int, what: str = "threshold") -> np.ndarray:
    """One table row, kept in the cache directory (``TOLLCLI_CACHE_DIR``) across processes.

    ``what``: "threshold" (the ETC thresholds over the grid) or "pfa" (their P_FA).
    The file name carries every input of the row and scipy's version; a missing or
    unreadable file is recomputed (and rewritten when the directory is writable).
    """
    import scipy

    from tollcli.cache import cached_array

    def compute() -> np.ndarray:
        if what == "pfa":
            return false_alarm_probability(_stored_row(p_md, scheme, grid, k), np.full(grid.shape, k))
        return etc_threshold(p_md, np.full(grid.shape, k), grid**2)

    name = f"etc-{what}-pmd{p_md!r}-{scheme}-n{grid.size}-k{k}-scipy{scipy.__version__}.npy"
    return cached_array("thresholds", name, compute, shape=grid.shape)


#: degrees of freedom the stored classic thresholds cover (more measurements than anyone tracks)
CLASSIC_DOF_MAX = 128


@lru_cache(maxsize=16)
def _classic_row(p_fa: float) -> np.ndarray:
    import scipy

    from tollcli.cache import cached_array

    dof = np.arange(CLASSIC_DOF_MAX + 1)
    name = f"classic-threshold-pfa{p_fa!r}-k{CLASSIC_DOF_MAX}-scipy{scipy.__version__}.npy"
    return cached_array("thresholds", name, lambda: classic_threshold(p_fa, dof), shape=dof.shape)


def stored_classic_threshold(p_fa: float, dof) -> np.ndarray:
    """:func:`classic_threshold` (χ²_dof's upper ``p_fa`` quantile) from a row kept in the cache directory: a
    second process needs no scipy.special for it."""
    dof = np.asarray(dof)
    row = _classic_row(float(p_fa))
    inside = (dof >= 1) & (dof <= CLASSIC_DOF_MAX)
    out = np.where(inside, row[np.clip(dof, 0, CLASSIC_DOF_MAX)], np.nan)
    if (dof > CLASSIC_DOF_MAX).any():
        out = np.where(dof > CLASSIC_DOF_MAX, classic_threshold(p_fa, dof), out)
    return out


@lru_cache(maxsize=16)
def etc_threshold_table(p_md: float) -> EtcThresholdTable:
    """The shared look-up table for ``p_md`` (a process builds each one once: its rows cost ~40 ms apiece)."""
    return EtcThresholdTable(p_md)


def false_alarm_probability(threshold, dof) -> np.ndarray:
    """P_FA = 1 − CDF_χ²_k(Th): the chance a fault-free position is rejected."""
    dof = np.asarray(dof, dtype=float)
    th = np.asarray(threshold, dtype=float)
    ok = (dof >= 1) & np.isfinite(th)
    return np.where(ok, _special().chdtrc(np.where(ok, dof, 1), np.where(ok, th, 0.0)), np.nan)  # = stats.chi2.sf


def p_mgor_max(invoice_share_pct: float, invoice_error_pct: float) -> float:
    """Largest P_MGoR meeting "I % of invoices within M_e %" (thesis eq. 5.5, worst case N_Go = ⌊100/M_e⌋ − 1)."""
    n_go = math.floor(100.0 / invoice_error_pct) - 1
    if n_go < 1:
        raise ValueError("invoice error must be below 50 %")
    return 1.0 - (invoice_share_pct / 100.0) ** (1.0 / n_go)


def p_fgor_max(invoice_share_pct: float, n_potential: int) -> float:
    """Largest P_FGoR with I % of invoices free of false recognition over N_PFGoR segments (eq. 5.10)."""
    return 1.0 - (invoice_share_pct / 100.0) ** (1.0 / n_potential)


def p_md_for_overcharge(n_th: int, n_faulty: int = 72, budget: float = 5e-7 / 1.32e-4) -> float:
    """P_MD with P(Bin(N_F,PSR, P_MD) ≥ N_Th) = budget (thesis eqs. 5.36–5.38, Table 5.2)."""
    from scipy import optimize, stats

    def excess(p: float) -> float:
        return float(stats.binom.sf(n_th - 1, n_faulty, p)) - budget

    return float(optimize.brentq(excess, 1e-15, 0.5, xtol=1e-15))
