"""Pseudorange errors: the nominal model with temporal correlation, and injected faults.

Nominal errors (thesis §4.5, eq. 4.79) are a first-order Gauss-Markov process per
satellite, sampled every Δt:

    u(k+1) = a·u(k) + √(1 − a²)·w(k),   w ~ N(0, 1),   ε = σ_PSR·u

with a = exp(−Δt/T_c), so that ε has variance σ² and correlation time T_c. (The
thesis prints a = 1 − exp(−1/T_c); that gives a = 0.18 for T_c = 5 s, i.e. almost
white errors, contradicting its own T_c, so the usual exp(−Δt/T_c) is used.)
T_c = 0 gives white errors. A satellite that rises starts from the stationary law.

Faults (thesis §4.4): a bias of ``bias_m`` on one satellite. Either at given start
times (seconds from the start), or as episodes that start at each epoch with
probability ``p_fault``·Δt/``duration_s`` (so that about ``p_fault`` of the time is
faulty). The faulty satellite is the visible one with the largest slope (the
hardest to detect, the papers' worst case) or a named one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter


def gauss_markov(n_epochs: int, n_sats: int, tc_s: float, dt_s: float, rng: np.random.Generator,
                 state: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Unit-variance correlated noise (E, S) and the last row (to continue in the next chunk)."""
    w = rng.standard_normal((n_epochs, n_sats))
    if tc_s <= 0 or n_epochs == 0:
        return w, (w[-1] if n_epochs else state)
    a = float(np.exp(-dt_s / tc_s))
    start = rng.standard_normal(n_sats) if state is None else state
    u, _ = lfilter([np.sqrt(1.0 - a * a)], [1.0, -a], w, axis=0, zi=(a * start)[None, :])
    return u, u[-1]


@dataclass
class FaultPlan:
    """Which epochs carry a fault, how big, on which satellite."""

    bias_m: float = 0.0
    at_s: list[float] = field(default_factory=list)  # episode start times
    p_fault: float = 0.0  # share of the time in fault episodes
    duration_s: float = 10.0
    sv: str | None = None  # e.g. "G05"; None = the visible satellite with the largest slope

    @property
    def active(self) -> bool:
        return self.bias_m != 0.0 and (bool(self.at_s) or self.p_fault > 0.0)


def fault_epochs(plan: FaultPlan, t_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Boolean (E,): epochs inside a fault episode."""
    faulty = np.zeros(t_s.size, dtype=bool)
    if not plan.active or t_s.size == 0:
        return faulty
    dt = float(np.median(np.diff(t_s))) if t_s.size > 1 else 1.0
    for s0 in plan.at_s:
        faulty |= (t_s >= s0) & (t_s < s0 + plan.duration_s)
    if plan.p_fault > 0:
        p_start = min(1.0, plan.p_fault * dt / max(plan.duration_s, dt))
        starts = np.cumsum(rng.random(t_s.size) < p_start)
        window = max(1, int(round(plan.duration_s / dt)))
        before = np.concatenate([np.zeros(window, dtype=starts.dtype), starts[:-window]])[: t_s.size]
        faulty |= (starts - before) > 0
    return faulty
