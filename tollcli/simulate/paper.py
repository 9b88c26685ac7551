"""The simulations behind the papers' figures (paper 001 §VI, thesis ch. 7), vectorized over epochs.

The papers' set-up: a vehicle at 50 km/h on the axis of a 20 m straight street
(axis north–south, thesis Fig. 7.3) at Perpignan, 1 Hz, nominal GPS 24 / Galileo 27,
5° mask, line-of-sight satellites only, 72 h. The satellites see a fixed point of
the Earth while the street's buildings pass by (the trajectory is "stationary"
for the sky, moving for the street).

Per receiver configuration (constellations × ionosphere model) the run keeps,
per epoch, what any RAIM setting needs: visible satellites, k (dof), the largest
slope and the fault-free test statistic t = εᵀΣ⁻¹(I − B)ε of correlated nominal
errors (one receiver clock: "3D + 1 clock"). Any (mode, HAL, P_MD, P_FA) is then
a cheap :func:`tollcli.integrity.raim.detect` over those arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from tollcli.gnss.sigma_models import NominalModel
from tollcli.gnss.wls import (
    observation_matrix,
    residuals_from_prefit,
    wls_geometry,
    wsse,
)
from tollcli.integrity.raim import VALID, RaimParams, detect
from tollcli.simulate.constellations import nominal, stacked
from tollcli.simulate.errors import gauss_markov
from tollcli.simulate.route import PERPIGNAN, stationary
from tollcli.simulate.sky import sky
from tollcli.simulate.streets import line_of_sight, make_street

RECEIVERS = {  # name → (constellations, ionosphere model)
    "gps_sbas": (("GPS",), "sbas"), "dual_sbas": (("GPS", "Galileo"), "sbas"),
    "gps_l1": (("GPS",), "single"), "dual_l1": (("GPS", "Galileo"), "single"),
    "gps_if": (("GPS",), "iono-free"), "dual_if": (("GPS", "Galileo"), "iono-free"),
}  # fmt: skip


@dataclass
class Run:
    """Per-epoch results of one receiver configuration (arrays of length E)."""

    n_visible: np.ndarray
    n_meas: np.ndarray
    dof: np.ndarray
    slope_max_m: np.ndarray
    singular: np.ndarray
    test_stat: np.ndarray
    horiz_error_m: np.ndarray

    def _geometry(self) -> SimpleNamespace:
        """What :func:`detect` reads of a geometry."""
        return SimpleNamespace(dof=self.dof, slope_max_m=self.slope_max_m, singular=self.singular, n_meas=self.n_meas)

    def status(self, params: RaimParams) -> np.ndarray:
        return detect(self._geometry(), self.test_stat, params).status

    def valid(self, params: RaimParams) -> np.ndarray:
        return self.status(params) == VALID

    def hpl_classic_m(self, params: RaimParams) -> np.ndarray:
        return detect(self._geometry(), self.test_stat, RaimParams("classic", params.hal_m, params.p_md, params.p_fa)).hpl_m


def simulate_runs(env: str, hours: float, receivers: list[str], seed: int = 0, tc_s: float = 5.0,
                  cn0_dbhz: float = 30.0, heading_deg: float = 0.0, speed_mps: float = 50 / 3.6,
                  chunk_epochs: int = 7200) -> tuple[dict[str, Run], dict[str, np.ndarray]]:  # fmt: skip
    """Runs per receiver, and the visible-satellite counts per constellation (for Tables 7.2–7.4)."""
    traj = stationary(PERPIGNAN[0], PERPIGNAN[1], heading_deg, speed_mps, hours * 3600.0)
    names, _, sats = stacked(nominal(["gps", "galileo"]))
    seeds = np.random.SeedSequence(seed).spawn(2)
    street = make_street(env, float(traj.s_m[-1]), np.random.default_rng(seeds[0]))
    noise_rng = np.random.default_rng(seeds[1])
    parts: dict[str, list] = {r: [] for r in receivers}
    counts: dict[str, list] = {"GPS": [], "Galileo": [], "GPS+Galileo": []}
    state = None
    for lo in range(0, traj.t_s.size, chunk_epochs):
        sl = slice(lo, min(lo + chunk_epochs, traj.t_s.size))
        view = sky(sats, traj.t_s[sl], traj.lat_deg[sl], traj.lon_deg[sl], traj.height_m[sl])
        elev, azim = view["elev_deg"], view["azim_deg"]
        visible = (elev >= 5.0) & line_of_sight(street, traj.s_m[sl], traj.heading_deg[sl], elev, azim)
        for key, sel in (("GPS", names == "GPS"), ("Galileo", names == "Galileo"), ("GPS+Galileo", np.ones(names.size, bool))):
            counts[key].append(visible[:, sel].sum(axis=1))
        unit, state = gauss_markov(elev.shape[0], names.size, tc_s, 1.0, noise_rng, state)
        H_all = observation_matrix(elev, azim, np.zeros(elev.shape, dtype=np.int64), 1)
        for r in receivers:
            consts, iono = RECEIVERS[r]
            cols = np.flatnonzero(np.isin(names, consts))
            mask = visible[:, cols]
            sigma = NominalModel(iono=iono, default_cn0_dbhz=cn0_dbhz).sigma_m(
                elev[:, cols], np.full(mask.shape, cn0_dbhz), names[cols][None, :], PERPIGNAN[0], PERPIGNAN[1])
            H = H_all[:, cols]
            g = wls_geometry(H, np.where(mask, sigma, np.nan), mask)
            eps = sigma * unit[:, cols]
            resid, dx = residuals_from_prefit(H, g, eps, mask)
            t = wsse(resid, g)
            parts[r].append((mask.sum(axis=1), g.n_meas, g.dof, g.slope_max_m, g.singular, t, np.hypot(dx[:, 0], dx[:, 1])))
    runs = {r: Run(*(np.concatenate(col) for col in zip(*parts[r]))) for r in receivers}
    return runs, {k: np.concatenate(v) for k, v in counts.items()}


def visibility_table(counts: np.ndarray) -> dict[int, float]:
    """Share of epochs with at least 4, 5, 6, 7 visible satellites."""
    return {k: float(np.mean(counts >= k)) for k in (4, 5, 6, 7)}


def missed_segment_probability(valid: np.ndarray, durations_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """p{no valid position} for trajectories of each duration (a trajectory starts every epoch).

    With N_Th = 1 the independence rule (wait T_c after a counted position) does
    not change whether one valid position exists; T_c acts through the error
    correlation. Returns the probabilities and the number of windows behind each.
    """
    c = np.concatenate([[0], np.cumsum(valid.astype(np.int64))])
    probs, windows = [], []
    for d in durations_s:
        d = int(d)
        n = valid.size - d + 1
        if n <= 0:
            probs.append(np.nan)
            windows.append(0)
            continue
        count = c[d : d + n] - c[:n]
        probs.append(float(np.mean(count == 0)))
        windows.append(n)
    return np.asarray(probs), np.asarray(windows)
