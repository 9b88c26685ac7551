"""The environment an epoch was measured in, from its own residuals: ``open`` or ``urban``.

The papers' error model (nominal σ, :mod:`tollcli.gnss.sigma_models`) holds in open country; in a street
canyon, reflected and non-line-of-sight signals make errors of tens of metres that it does not bound (the
Potsdamer Platz drive: 27 m median, 79 m worst, about 6 nominal σ_major). The residuals tell which world an
epoch is in. Under the model the test statistic is χ²; its **robust variance factor**, pooled over the epochs
of the last ``ENV_WINDOW_S`` seconds (the epoch itself included),

    f = Σ t₍ⱼ₎ / Σ (k − 1),   t₍ⱼ₎ = t without the epoch's most deviating measurement,

stays below 1 where the model holds (dropping the largest term of a χ² lowers it) and whatever one faulty
satellite does — that is the RAIM's to detect, not a reason to widen the model — while many deviating
measurements at once, a street canyon, raise it. An epoch is ``urban`` where f > ``F_URBAN`` (1.5); its
measurements then get the urban σ of :func:`tollcli.gnss.sigma_models.urban_sigma_m` (C/N0-weighted: NLOS
signals, weaker, count less); elsewhere the σ stays as the error model gave it. There is no middle ground on
purpose: widening the nominal σ by the measured factor widens the RAIM's thresholds faster than its bound and
let Potsdamer Platz positions more than 50 m off through when it was tried; the urban σ lets none through.

Epochs without residuals have no f: they keep their σ (``environment`` ''); ``--environment open`` keeps the
error model throughout, ``--environment urban`` makes every epoch urban. The ``model`` bound (a covariance
from the satellites' geometry alone, :mod:`tollcli.integrity.model_bound`) gets the σ of the environment the
residuals measured, and the urban σ where nothing measured one: a receiver that reports only its satellites
shows no sign of a street canyon, so its bound cannot assume open country — ``--environment open`` declares
it (a motorway network in open country) and the nominal σ then holds (shown on the GSDC drives, not on
Potsdamer Platz: docs/integrity.md). An epoch whose fix the receiver says is corrected (DGNSS/SBAS, RTK fixed
or float: :attr:`Measurements.corrected_fix`) keeps its corrected σ where nothing measured the environment.

Measured (``benchmarks/integrity_truth.py``, docs/integrity.md): f is 1.53–9.95 on the Potsdamer Platz drive
(median 3.96; the epochs the nominal σ would let through have 2.2 or more), 0.03–0.72 on the simulator's
fault-free urban and rural drives (their errors are the nominal model's), at most 2.1 during the simulated
single-satellite faults, and 0.6–1.3 on the GSDC 2021 Pixel 4 epochs under the nominal model (1.7–3.0 under
the phone's own, smaller σ: those epochs are urban).

The window runs across the chunks of a streamed log (:class:`EnvironmentCarry`), each window summed over its own
epochs, so a log read in chunks gets the same classes as read whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.sigma_models import urban_sigma_m
from tollcli.gnss.wls import post_fit_residuals, wls_geometry, wsse

ENVIRONMENTS = ("auto", "open", "urban")
ENV_WINDOW_S = 30.0
F_URBAN = 1.5


@dataclass
class EnvironmentCarry:
    """The last window's epochs (time, t, k) of the chunks before, for a log read chunk by chunk."""

    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    k: np.ndarray = field(default_factory=lambda: np.zeros(0))


def robust_statistics(meas: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """The residual test statistic of every epoch under ``meas``'s own σ **without its most deviating
    measurement**, t₍ⱼ₎ = t − r_j² / (σ_j² (I − B)_jj) for the largest such term, and its k − 1 degrees of
    freedom: one faulty satellite (what the RAIM detects) does not widen the model; many deviating ones (a
    street canyon) do. Epochs with k < 2 count nothing (k 0); a batch without a residual gives t NaN and k 0
    throughout."""
    from tollcli.gnss.wls import REDUNDANCY_EPS

    n = meas.mask.shape[0]
    if meas.dy_m is None and (meas.residual_m is None or not np.isfinite(meas.residual_m).any()):
        return np.full(n, np.nan), np.zeros(n)  # no residuals: nothing to measure (and no geometry to solve)
    geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
    residual, _ = post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, meas.residual_m)
    t = wsse(residual, geometry)
    checked = (geometry.weight > 0) & (geometry.redundancy > REDUNDANCY_EPS)
    with np.errstate(divide="ignore", invalid="ignore"):
        term = np.where(checked, geometry.weight * np.nan_to_num(residual) ** 2 / np.where(checked, geometry.redundancy, 1.0), 0.0)
    worst = term.max(axis=1, initial=0.0) if term.shape[1] else np.zeros(n)
    k = geometry.dof.astype(float) - 1.0
    return np.where(k >= 1, np.maximum(t - worst, 0.0), np.nan), np.where(k >= 1, k, 0.0)


def variance_factor(time_s: np.ndarray, t: np.ndarray, k: np.ndarray, window_s: float = ENV_WINDOW_S,
                    carry: EnvironmentCarry | None = None) -> np.ndarray:  # fmt: skip
    """Pooled Σt/Σk over the trailing ``window_s`` of each epoch (NaN where no epoch of the window has a t).

    ``time_s`` ascending seconds (any origin shared with ``carry``); ``carry`` is read and then updated.
    """
    ok = np.isfinite(t) & (k > 0) & np.isfinite(time_s)
    tt, kk = np.where(ok, t, 0.0), np.where(ok, k, 0.0)
    ts = np.fmax.accumulate(np.where(np.isfinite(time_s), time_s, np.nan)) if time_s.size else time_s
    ts = np.where(np.isfinite(ts), ts, -np.inf)  # an undated epoch before any dated one: a window of its own
    if carry is not None and carry.time_s.size and ts.size and not carry.time_s[-1] <= ts[0]:
        carry.time_s, carry.t, carry.k = np.zeros(0), np.zeros(0), np.zeros(0)  # times that do not follow on
    if carry is not None:
        ts_all = np.concatenate([carry.time_s, ts])
        t_all, k_all = np.concatenate([carry.t, tt]), np.concatenate([carry.k, kk])
    else:
        ts_all, t_all, k_all = ts, tt, kk
    n_before = ts_all.size - ts.size
    start = np.searchsorted(ts_all, ts - window_s, side="right")
    end = np.arange(n_before, ts_all.size) + 1
    sum_t, sum_k = _window_sums(t_all, start, end), _window_sums(k_all, start, end)
    if carry is not None and ts_all.size:
        keep = ts_all > ts_all[-1] - window_s
        carry.time_s, carry.t, carry.k = ts_all[keep], t_all[keep], k_all[keep]
    have = sum_k > 0
    return np.where(have, sum_t / np.where(have, sum_k, 1.0), np.nan)


def _window_sums(x: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Σ x[start:end] per window, each summed over its own elements only (not as a difference of running sums),
    so a window gives the same float whichever chunk it was computed in."""
    if start.size == 0:
        return np.zeros(0)
    pairs = np.stack([start, end], axis=1).ravel()
    sums = np.add.reduceat(np.append(x, 0.0), pairs)[::2]
    return np.where(end > start, sums, 0.0)


def classify(factor: np.ndarray, setting: str = "auto") -> np.ndarray:
    """'urban', 'open' or '' (no residuals to tell) per epoch; ``setting`` 'open'/'urban' fixes it."""
    if setting not in ENVIRONMENTS:
        raise ValueError(f"--environment {setting}: use one of {', '.join(ENVIRONMENTS)}")
    if setting != "auto":
        return np.full(factor.shape, setting, dtype=object)
    return np.where(np.isfinite(factor), np.where(factor > F_URBAN, "urban", "open"), "").astype(object)


def with_environment(meas: Measurements, time_s: np.ndarray, setting: str = "auto",
                     carry: EnvironmentCarry | None = None) -> tuple[Measurements, np.ndarray, np.ndarray]:  # fmt: skip
    """``meas`` with the urban σ on its urban epochs, each epoch's class and its robust variance factor.

    ``setting`` open: ``meas`` unchanged (the error model throughout; the classes the residuals give are still
    reported); urban: the urban σ on every epoch.
    """
    t, k = robust_statistics(meas)
    factor = variance_factor(np.asarray(time_s, float), t, k, carry=carry)
    measured = np.isfinite(factor)
    if setting == "open":
        n = meas.mask.shape[0]
        return replace(meas, model_sigma_m=meas.sigma_m, model_open=np.ones(n, bool), env_measured=measured), classify(factor), factor
    env = classify(factor, setting)
    urban = env == "urban"
    open_sky = env == "open"
    if open_sky.all():  # the error model holds throughout: nothing to widen (the arrays stay the very same)
        return replace(meas, model_sigma_m=meas.sigma_m, model_open=open_sky, env_measured=measured), env, factor
    urban_sigma = _urban_sigma(meas)
    sigma = np.where(urban[:, None], urban_sigma, meas.sigma_m) if urban.any() else meas.sigma_m
    corrected = (env == "") & (meas.corrected_fix if meas.corrected_fix is not None else np.zeros(env.shape, bool))
    keep = open_sky | corrected  # unknown: the urban σ (no residual says open), but for a corrected fix
    model = np.where(keep[:, None], meas.sigma_m, urban_sigma)
    return replace(meas, sigma_m=sigma, model_sigma_m=model, model_open=keep, env_measured=measured), env, factor


def _urban_sigma(meas: Measurements) -> np.ndarray:
    """(E, N) each used measurement's urban σ (never below its own), m."""
    return np.where(meas.mask, np.maximum(meas.sigma_m, urban_sigma_m(meas.sigma_m, meas.cn0_dbhz)), meas.sigma_m)


def with_declared_environment(meas: Measurements, declared: np.ndarray, setting: str = "auto") -> Measurements:
    """``meas`` (one row per position and geo-object) with the ``model`` level's σ of the environment the operator
    declared for each row's geo-object (``declared``: 'open', 'urban' or '' none), where the residuals measured none.

    The declaration stands in for evidence the receiver does not give (a tracker that reports only its satellites):
    ``open`` — a motorway outside built-up land, as the operator declares it — gives the error model's σ; ``urban``
    the urban σ (a corrected fix included). Where the residuals measured the environment they decide, as they do
    everywhere. Never weaker than an explicit ``--environment``: ``urban`` given keeps every row urban; ``open``
    given already takes the error model, and a declared ``urban`` still widens it.
    """
    declared = np.asarray(declared, dtype=object)
    measured = meas.env_measured if meas.env_measured is not None else np.zeros(declared.shape, bool)
    free = ~measured & (setting != "urban")
    as_open = free & (declared == "open") & (setting == "auto")
    as_urban = free & (declared == "urban")
    if not (as_open.any() or as_urban.any()):
        return meas
    sigma = meas.model_sigma_m if meas.model_sigma_m is not None else meas.sigma_m
    open_sky = meas.model_open.copy() if meas.model_open is not None else np.zeros(declared.shape, bool)
    urban_sigma = _urban_sigma(meas)
    model = np.where(as_open[:, None], meas.sigma_m, np.where(as_urban[:, None], urban_sigma, sigma))
    open_sky[as_open] = True
    open_sky[as_urban] = False
    return replace(meas, model_sigma_m=model, model_open=open_sky)
