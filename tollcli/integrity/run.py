"""Estimate → detect → exclude, over a batch of epochs: the integrity columns.

Columns added to the epoch table (names as in the papers, units in the names):
``raim_mode``, ``n_used`` (measurements in the RAIM), ``dof`` (k), ``slope_max_m``,
``test_stat`` (WSSE), ``test_stat_source`` (grs, gst, pseudorange, none),
``threshold``, ``lambda_det``, ``hpl_m``, ``hal_m``, ``p_fa``, ``p_md``,
``raim_status`` (the strictest verdict of every integrity source, :mod:`tollcli.integrity.sources`),
``integrity_source`` (the source that decided it), ``residual_status``/``gbs_status``/``gst_status``
(each source's own verdict, '' where it gave none), ``wls_shift_e_m``/``wls_shift_n_m`` (where the RAIM's own
weighted solution lies from the reported position: pseudoranges solved with other weights, e.g. the urban σ), ``hpl_gbs_m``/``hpl_gst_m`` (the receiver's
bounds; the satellite a GBS names as failed is the epoch table's ``gbs_failed_svid``), ``hpl_model_m`` (the
``model`` bound: geometry and error model, :mod:`tollcli.integrity.model_bound`), ``gst_rms_note`` (why a GST RMS was ignored), ``excluded_sv``, ``fde_shift_e_m``/``fde_shift_n_m`` (how far the
position moves when the excluded measurement is dropped), ``hpl_sbas_m`` (paper 004's
K_H·d_major from the per-satellite σ's: an accuracy bound, not a RAIM output).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements
from tollcli.gnss.receiver_outputs import GST_RMS_NOTES
from tollcli.gnss.wls import Geometry, horizontal_covariance, post_fit_residuals, wls_geometry, wsse
from tollcli.integrity.fde import exclude
from tollcli.integrity.kalman_hit import hpl_sbas_m
from tollcli.io.columns import text_of_codes
from tollcli.integrity.raim import (
    EXCLUDED,
    FAULT,
    INSUFFICIENT,
    PROBABLE_FALSE_ALARM,
    STATUSES,
    UNAVAILABLE,
    UNMONITORED,
    VALID,
    RaimParams,
    detect,
)
from tollcli.integrity.solution_separation import (
    SeparationResult,
    epoch_separation,
    take_separation,
    separation_detection,
    separation_exclusion,
)
from tollcli.integrity.sources import (
    LEVELS,
    NONE,
    RESIDUAL_SOURCES,
    bound_verdict,
    combine,
    k_h,
    level_for,
    receiver_verdicts,
    strictest,
)

RAIM_COLUMNS = (
    "raim_mode", "n_used", "dof", "slope_max_m", "test_stat", "test_stat_source", "threshold", "lambda_det",
    "hpl_m", "hal_m", "p_fa", "p_md", "raim_status", "integrity_source", "residual_status", "gbs_status", "gst_status",
    "hpl_gbs_m", "hpl_gst_m", "hpl_model_m", "gst_rms_note", "excluded_sv", "fde_shift_e_m", "fde_shift_n_m", "wls_shift_e_m", "wls_shift_n_m",
    "hpl_sbas_m", "separation_ratio",
)  # fmt: skip
_STATUS_OR_NONE = np.array(STATUSES + ("",), dtype=object)  # index -1: no verdict


def run_raim(meas: Measurements, params: RaimParams, hal_m=None, geometry: Geometry | None = None,
             hal_free: HalFreeTerms | None = None) -> pd.DataFrame:  # fmt: skip
    """One row of RAIM results per epoch of ``meas`` (``hal_m``: scalar or per epoch).

    ``geometry``: ``wls_geometry`` of ``meas`` when already computed (it does not depend on the HAL);
    ``hal_free``: :func:`hal_free_terms` of ``meas`` when already computed (nor do they). Epochs the
    trajectory estimator placed are judged by its bound and fault test instead (:mod:`tollcli.integrity.trajectory_verdicts`).
    """
    if meas.trajectory_hpl_m is not None:
        from tollcli.integrity.trajectory_verdicts import trajectory_raim

        return trajectory_raim(meas, params, hal_m)
    if geometry is None:
        geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
    n_epochs = meas.mask.shape[0]
    residual, correction = post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, meas.residual_m)
    wls_shift = np.where(np.isfinite(correction[:, :2]), correction[:, :2], 0.0)  # its own solution from the reported
    t = wsse(residual, geometry)
    per_satellite = np.isfinite(t)  # residuals of every used measurement (not a GST approximation)
    if meas.test_stat_override is not None:
        t = np.where(np.isnan(t), meas.test_stat_override, t)
    excluded_sv = np.full(n_epochs, "", dtype=object)
    shift = np.zeros((n_epochs, 3))
    ratio = np.full(n_epochs, np.nan)
    if params.mode == "ss":
        detection, ratio = separation_detection(meas.H, meas.sigma_m, meas.mask, np.where(per_satellite[:, None], residual, np.nan),
                                                geometry, t, params, hal_m, hal_free.separation if hal_free else None)  # fmt: skip
        if params.fde:
            excluded_sv, shift = separation_exclusion(meas, geometry, residual, detection, ratio, params)
    else:
        detection = detect(geometry, t, params, hal_m=hal_m)
    if params.fde and params.mode != "ss":
        exclusion = exclude(meas.H, meas.sigma_m, meas.mask, residual, geometry, detection, params)
        hit = exclusion.excluded_slot >= 0
        excluded_sv[hit] = meas.sv[np.flatnonzero(hit), exclusion.excluded_slot[hit]]
        shift = exclusion.shift_enu_m
    source = meas.test_stat_source
    if source is None:  # residuals given directly: a residual test
        source = np.where(np.isfinite(t), "pseudorange" if meas.dy_m is not None else "grs", "none").astype(object)
    status = detection.status.copy()
    status[probable_false_alarms(status, detection.test_stat, detection.dof, detection.p_fa, params.p_fa)] = PROBABLE_FALSE_ALARM
    if meas.satellites_reported is not None:  # a receiver that reports no satellites at all (GGA/RMC only): nothing
        status[~meas.satellites_reported & (geometry.n_meas == 0)] = STATUSES.index("unmonitored")  # to monitor, not "too few"
    hpl_model = hal_free.model_hpl_m if hal_free is not None and hal_free.model_hpl_m is not None else model_hpl(meas, geometry, params.p_md)
    verdicts, extra = _source_verdicts(meas, status, source, detection.hal_m, params, hpl_model)
    undecided = np.where(np.isin(status, (INSUFFICIENT, UNMONITORED)), status, UNMONITORED)  # no allowed source decided
    allowed = _allowed(meas, params)
    if "model" not in allowed:  # the weakest evidence denies nothing a stronger level vouches for
        verdicts["model"] = np.full(n_epochs, NONE)
    final, deciding = combine(verdicts, allowed, undecided)
    return pd.DataFrame(
        {
            "raim_mode": text_of_codes(np.zeros(n_epochs, np.int8), (params.mode,)),
            "n_used": geometry.n_meas.astype(np.int16),
            "dof": detection.dof.astype(np.int16),
            "slope_max_m": detection.slope_max_m,
            "test_stat": detection.test_stat,
            "test_stat_source": pd.array(source, dtype="string"),
            "threshold": detection.threshold,
            "lambda_det": detection.lambda_det,
            "hpl_m": detection.hpl_m,
            "hal_m": detection.hal_m,
            "p_fa": detection.p_fa,
            "p_md": np.full(n_epochs, params.p_md),
            "raim_status": text_of_codes(final, STATUSES),
            "integrity_source": pd.array(deciding, dtype="string"),
            "residual_status": _names(verdicts["grs"] if "grs" in verdicts else verdicts["pseudorange"]),
            "gbs_status": _names(verdicts["gbs"]),
            "gst_status": _names(verdicts["gst"]),
            **extra,
            "excluded_sv": pd.array(excluded_sv, dtype="string"),
            "fde_shift_e_m": shift[:, 0],
            "fde_shift_n_m": shift[:, 1],
            "wls_shift_e_m": wls_shift[:, 0],
            "wls_shift_n_m": wls_shift[:, 1],
            "hpl_sbas_m": hpl_sbas_m(geometry, meas.sigma_m),
            "separation_ratio": ratio,
        }
    )


@dataclass
class HalFreeTerms:
    """What :func:`run_raim` computes per epoch that depends on neither the HAL nor exclusion: the solution
    separation (None: not the ``ss`` mode) and the ``model`` level's HPL (None: to be computed, as for positions whose
    model σ a geo-object's declared environment changed). Computed once for a chunk of a log, they serve the epochs'
    RAIM and every (epoch, geo-object) pair's (:func:`tollcli.charging.recognition.inside_pairs`)."""

    separation: SeparationResult | None
    model_hpl_m: np.ndarray | None

    def take(self, rows: np.ndarray, model: bool = True) -> HalFreeTerms:
        """The terms of epochs ``rows`` (repeats allowed); without the model HPL unless ``model``."""
        return HalFreeTerms(None if self.separation is None else take_separation(self.separation, rows),
                            self.model_hpl_m[rows] if model and self.model_hpl_m is not None else None)  # fmt: skip


def hal_free_terms(meas: Measurements, params: RaimParams, geometry: Geometry, model_hpl_m: np.ndarray | None = None,
                   untested: bool = True) -> HalFreeTerms | None:  # fmt: skip
    """:class:`HalFreeTerms` of ``meas`` (None: positions the trajectory estimator placed, judged by its bound);
    ``model_hpl_m``: :func:`model_hpl` of ``meas`` when already computed (with ``params.p_md``).

    ``untested``: False when the caller reads no epoch's ``hpl_m`` but where the residual test decides (a ``process``
    without map matching or an epoch table): the solution separation is then solved only for the epochs whose
    separation some verdict reads (:func:`separation_read`), and the others' ``hpl_m`` is NaN. Their statuses and every
    other column are the same (``tests/test_separation_untested.py``); on a receiver that writes no range residuals
    (the 10 h NEO-M9N NMEA drive of ``benchmarks/process_throughput.py``) no epoch is solved at all."""
    if meas.trajectory_hpl_m is not None:
        return None
    separation = None
    if params.mode == "ss":
        residual, _ = post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, meas.residual_m)
        t = wsse(residual, geometry)
        per_satellite = np.isfinite(t)
        rows = None if untested else np.flatnonzero(separation_read(meas, t))
        separation = epoch_separation(meas.H, meas.sigma_m, meas.mask, np.where(per_satellite[:, None], residual, np.nan),
                                      geometry, params, rows=rows)  # fmt: skip
    return HalFreeTerms(separation, model_hpl(meas, geometry, params.p_md) if model_hpl_m is None else model_hpl_m)


def separation_read(meas: Measurements, test_stat: np.ndarray) -> np.ndarray:
    """(E,) the epochs whose solution separation a verdict reads: those with a test statistic (``test_stat``, the WSSE
    of :func:`wsse`, NaN where a used residual is missing; a GST RMS's statistic stands in, as in :func:`run_raim`) or
    whose statistic's source is a residual one or a GST (their status there — ``unavailable`` when the HPL exceeds the
    HAL, else ``unmonitored`` — is that source's verdict). For every other epoch the residual test's status falls to
    ``unmonitored`` whatever its HPL: only its ``hpl_m`` column reads the separation."""
    t = test_stat
    if meas.test_stat_override is not None:
        t = np.where(np.isnan(t), meas.test_stat_override, t)
    read = np.isfinite(t)
    if meas.test_stat_source is not None:
        read |= meas.test_stat_source != "none"
    return read


def _names(verdict: np.ndarray):
    return text_of_codes(verdict, _STATUS_OR_NONE)


def _source_verdicts(meas: Measurements, status: np.ndarray, source: np.ndarray, hal_m: np.ndarray, params: RaimParams,
                     hpl_model: np.ndarray):  # fmt: skip
    """Each source's verdict codes (-1: none), in SOURCES order, and the receiver's and the model's columns
    (``hpl_model``: :func:`model_hpl`)."""
    n = status.size
    decided = np.isin(status, (VALID, FAULT, EXCLUDED, UNAVAILABLE, PROBABLE_FALSE_ALARM))
    residual = np.where(decided & np.isin(source, RESIDUAL_SOURCES), status, NONE)
    name = "pseudorange" if np.any(source == "pseudorange") else "grs"
    verdicts = {name: residual}
    hal = np.broadcast_to(hal_m, (n,))
    r = meas.receiver
    if r is None:
        verdicts["gbs"] = verdicts["gst"] = np.full(n, NONE)
        verdicts["model"] = bound_verdict(hpl_model, hal)
        nan = np.full(n, np.nan)
        return verdicts, {"hpl_gbs_m": nan, "hpl_gst_m": nan, "hpl_model_m": hpl_model,
                          "gst_rms_note": text_of_codes(np.zeros(n, np.int8), ("",))}  # fmt: skip
    own = receiver_verdicts(r, hal, params.p_md, params.p_fa)
    gst_rms = np.where(decided & (source == "gst"), status, NONE)
    verdicts["gbs"] = own["gbs"]
    verdicts["gst"] = strictest(gst_rms, own["gst_bound"])
    verdicts["model"] = bound_verdict(hpl_model, hal)
    return verdicts, {"hpl_gbs_m": own["hpl_gbs_m"], "hpl_gst_m": own["hpl_gst_m"], "hpl_model_m": hpl_model,
                      "gst_rms_note": text_of_codes(r.gst_rms_note, GST_RMS_NOTES)}  # fmt: skip


def model_hpl(meas: Measurements, geometry: Geometry, p_md: float) -> np.ndarray:
    """The ``model`` level's HPL per epoch (m): K_H·σ_major of the used satellites' geometry under the model σ
    (:attr:`Measurements.model_sigma_m`; the urban σ where it is not set), else — where the receiver reports no
    satellites at all — K_H·HDOP·σ_worst, else NaN (satellites reported, too few used: ``insufficient``)."""
    from tollcli.gnss.sigma_models import urban_sigma_m
    from tollcli.integrity.model_bound import hdop_hpl_m, major_of_covariance_m, model_hpl_m

    if meas.model_sigma_m is not None:
        sigma = meas.model_sigma_m
        open_sky = meas.model_open if meas.model_open is not None else np.zeros(meas.mask.shape[0], bool)
    else:  # nothing measured the environment: the urban σ, but for a corrected fix (its corrected σ)
        open_sky = meas.corrected_fix if meas.corrected_fix is not None else np.zeros(meas.mask.shape[0], bool)
        sigma = np.where(meas.mask & ~open_sky[:, None], np.maximum(meas.sigma_m, urban_sigma_m(meas.sigma_m, meas.cn0_dbhz)),
                         meas.sigma_m)  # fmt: skip
    same = sigma is meas.sigma_m or np.array_equal(np.where(meas.mask, sigma, 0.0), np.where(meas.mask, meas.sigma_m, 0.0))
    if same:
        hpl = model_hpl_m(geometry, sigma, p_md)
    else:  # its covariance only
        cov_en_m2, singular, n_meas = horizontal_covariance(meas.H, sigma, meas.mask)
        hpl = k_h(p_md) * major_of_covariance_m(cov_en_m2, singular | (n_meas == 0))
    if meas.receiver is not None and meas.receiver.hdop is not None:
        hpl = np.where(np.isfinite(hpl) | ~no_geometry(meas), hpl, hdop_hpl_m(meas.receiver.hdop, p_md, open_sky))
    return hpl


def model_level_read(params: RaimParams) -> bool:
    """Whether a verdict can read the ``model`` level's HPL under ``params``: its sources include that level, or are
    not settled yet (each chunk's own level then decides, :func:`_allowed`). Where not, :func:`run_raim` sets the model's
    verdict aside (the weakest evidence denies nothing a stronger level vouches for), and only the ``hpl_model_m``
    column shows that HPL."""
    return params.sources is None or "model" in params.sources


def no_geometry(meas: Measurements) -> np.ndarray:
    """Epochs (E,) whose satellites' geometry is not known: none reported, or none used with its angles (gpsd gives a
    Javad GREIS receiver's satellites without elevations; a GSA names the used ones before the first GSV gives their
    angles). The receiver's HDOP bounds those fixes (the ``model`` level)."""
    unreported = ~meas.satellites_reported if meas.satellites_reported is not None else np.ones(meas.mask.shape[0], bool)
    return unreported | ~meas.mask.any(axis=1)


def _allowed(meas: Measurements, params: RaimParams) -> tuple[str, ...]:
    """The sources that may validate: the params', else the strictest level these epochs support."""
    if params.sources is not None:
        return params.sources
    return LEVELS[level_of(meas) or "residual"]


def settle_sources(params: RaimParams, meas: Measurements) -> RaimParams:
    """``params`` with its sources fixed for the rest of a log: unchanged when set or when no epoch of
    ``meas`` has a source yet; else the strictest level ``meas`` supports (call it chunk after chunk)."""
    if params.sources is not None:
        return params
    level = level_of(meas, with_hdop=False)  # a GGA's HDOP at a log's first epoch, before its satellites: not yet
    if level is None and meas.satellites_reported is not None and not meas.satellites_reported.any():
        level = level_of(meas)  # no satellites in the whole chunk: a receiver that reports its HDOP only
    return params if level is None else replace(params, sources=LEVELS[level])


def level_name(sources: tuple[str, ...] | None) -> str | None:
    """The level of a tuple of sources (None for None)."""
    return next((name for name, s in LEVELS.items() if s == sources), None) if sources is not None else None


def level_of(meas: Measurements, with_hdop: bool = True) -> str | None:
    """The strictest level the epochs of ``meas`` support, from the first epoch that has any source (None: none has).

    ``with_hdop``: an HDOP alone (no satellites) counts as the ``model`` level's source."""
    n = meas.mask.shape[0]
    if meas.test_stat_source is not None:
        residual = np.isin(meas.test_stat_source, RESIDUAL_SOURCES)
    else:  # residuals or pseudoranges given directly: a residual test wherever there are measurements
        residual = np.full(n, meas.residual_m is not None or meas.dy_m is not None) & meas.mask.any(axis=1)
    r = meas.receiver
    gbs = (np.isfinite(r.gbs_sigma_major_m) | (r.gbs_failed_svid >= 0)) if r is not None else np.zeros(n, bool)
    gst = (np.isfinite(r.gst_sigma_major_m) | np.isfinite(r.gst_rms_m)) if r is not None else np.zeros(n, bool)
    model = meas.mask.sum(axis=1) >= 4  # a geometry to bound (or, below, an HDOP)
    if with_hdop and r is not None and r.hdop is not None:
        model |= no_geometry(meas) & np.isfinite(r.hdop) & (r.hdop > 0) & (r.hdop < 99)
    anything = np.flatnonzero(residual | gbs | gst | model)
    if not anything.size:
        return None
    i = int(anything[0])
    return level_for(bool(residual[i]), bool(gbs[i]), bool(gst[i]), bool(model[i]))


def probable_false_alarms(status: np.ndarray, test_stat: np.ndarray, dof: np.ndarray, epoch_p_fa: np.ndarray,
                          p_fa: float) -> np.ndarray:  # fmt: skip
    """Alarms (``FAULT``) that are probably false: the epoch's threshold has a false-alarm probability above
    ``p_fa`` (ETC) **and** the test statistic does not exceed what a fault-free χ²_dof passes with probability
    ``p_fa`` either. An exceedance so large that no fault-free test would reach it at ``p_fa`` (a 750 m outlier:
    t 250 000 × Th) stays ``fault_detected``, whatever the epoch's threshold."""
    from tollcli.integrity.design import stored_classic_threshold

    alarm = (status == FAULT) & np.isfinite(test_stat) & (dof >= 1)
    with np.errstate(invalid="ignore"):
        loose = alarm & (epoch_p_fa > p_fa)
    out = np.zeros(status.shape, bool)
    if loose.any():
        out[loose] = test_stat[loose] <= stored_classic_threshold(p_fa, dof[loose])
    return out
