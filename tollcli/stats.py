"""Small statistics shared by the integrity checks, the findings and the audit: the Wilson score interval,
the binomial upper tail, the median of a vector (numpy only: no scipy import on a command's start-up path)."""

from __future__ import annotations

import math

import numpy as np

Z95 = 1.959963984540054


def wilson(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (0, 1 for no trials)."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    centre = (p + z * z / (2 * trials)) / (1 + z * z / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / (1 + z * z / trials)
    return max(0.0, centre - half), min(1.0, centre + half)


def binomial_tail(k: np.ndarray, n: np.ndarray, p: np.ndarray) -> np.ndarray:
    """P(X ≥ k) for X ~ Binomial(n, p), element-wise (exact sum of the terms, in logs; numpy only).

    Used on a few candidate windows (n ≤ a window's epochs), so the (windows × n) table stays small.
    """
    k, n = np.asarray(k, np.int64), np.asarray(n, np.int64)
    p = np.clip(np.asarray(p, float), 1e-300, 1.0)
    if k.size == 0:
        return np.zeros(0)
    top = int(n.max(initial=0))
    log_fact = np.concatenate([[0.0], np.cumsum(np.log(np.arange(1, top + 1)))])
    j = np.arange(top + 1)[None, :]
    nn, kk, pp = n[:, None], k[:, None], p[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_q = np.where(pp < 1.0, np.log1p(-pp), -np.inf)
        log_term = (log_fact[nn] - log_fact[j] - log_fact[np.clip(nn - j, 0, None)] + j * np.log(pp)
                    + np.where(nn - j > 0, (nn - j) * log_q, 0.0))  # fmt: skip
    terms = np.where((j >= kk) & (j <= nn), np.exp(log_term), 0.0)
    return np.minimum(terms.sum(axis=1), 1.0)


def median(a: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D array without NaN — the same number (the middle one, or the two middle ones'
    sum halved) — from one partition and no checks: ~5× faster on the thousands of residuals of a satellite."""
    k = a.size // 2
    part = np.partition(a, k)
    return part[k] if a.size % 2 else (part[:k].max() + part[k]) / 2
