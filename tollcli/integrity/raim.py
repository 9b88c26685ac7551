"""WLSR RAIM fault detection, classic and ETC, batched over epochs (paper 001 §III–IV).

Statuses, in the order they are decided:

``insufficient``   fewer measurements than unknowns + 1 (k < 1) or singular geometry
``unavailable``    classic: HPL > HAL; ETC: a measurement no other one checks
                   (slope ∞) or no threshold > 0 keeps P_MD
``unmonitored``    geometry is fine but the log gives no test statistic (no residuals):
                   slopes, HPL and Th are reported, the position is never ``valid``
``fault_detected`` t > Th at a false-alarm probability P_FA ≤ ``p_fa`` (the alarm is credible)
``probable_false_alarm`` t > Th, but this epoch's P_FA > ``p_fa`` and t is no larger than a fault-free
                   χ²_k exceeds with probability ``p_fa`` (ETC only: to keep P_MD at the HAL the threshold was
                   set so low that the test fails often without any fault; the position is not trusted — not
                   charged on — but it is no evidence of a fault or an attack). A larger t is ``fault_detected``
                   whatever the threshold: the size of the exceedance is the evidence
``excluded_valid`` (FDE only) t > Th, and exactly one subset without one satellite passes
``valid``          t ≤ Th (and, classic, HPL ≤ HAL)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tollcli.gnss.wls import Geometry
from tollcli.integrity import design

STATUSES = ("valid", "fault_detected", "excluded_valid", "unavailable", "unmonitored", "insufficient", "probable_false_alarm")
VALID, FAULT, EXCLUDED, UNAVAILABLE, UNMONITORED, INSUFFICIENT, PROBABLE_FALSE_ALARM = range(7)
MODES = ("ss", "etc", "classic")
#: what each status tells an auditor (reports and invoices quote these)
STATUS_MEANINGS = {
    "valid": "the RAIM test passed (t ≤ Th): the position is trusted within the HAL",
    "excluded_valid": "the test failed, one satellite was excluded and the rest passed: trusted",
    "fault_detected": "the test failed at a false-alarm probability P_FA ≤ p_fa: a credible alarm, probably a fault",
    "probable_false_alarm": (
        "the test failed, but at this epoch's geometry P_FA > p_fa: to keep P_MD at the HAL the ETC RAIM lowers its "
        "threshold until the test often fails with no fault at all (HPL = HAL is bought with false alarms). The "
        "position is not trusted and never charged on, but the alarm alone is no evidence of a fault or of tampering. "
        "An alarm whose test statistic a fault-free test would not reach even at p_fa is fault_detected instead"
    ),
    "unavailable": "the geometry cannot protect the HAL (classic: HPL > HAL; ETC: a measurement nothing checks)",
    "unmonitored": "the log gives no test statistic (no residuals): not checked, never trusted",
    "insufficient": "too few satellites for a check (fewer than unknowns + 1) or a singular geometry",
}


@dataclass
class RaimParams:
    """What the RAIM is asked to guarantee."""

    #: "ss" (solution separation: multiple faults, HPL from the fault modes, the default), "etc" (paper 001's
    #: toll variant: HPL = HAL, P_FA varies) or "classic" (paper 001's civil-aviation RAIM: P_FA fixed, HPL varies)
    mode: str = "ss"
    hal_m: float = 50.0
    p_md: float = 5e-5
    p_fa: float = 5e-3  # classic: the design P_FA; ETC: an alarm above it is a probable_false_alarm
    fde: bool = False
    p_sat: float = 1e-5  # ss: prior probability of a satellite fault
    p_const: float = 1e-8  # ss: prior probability of a constellation-wide fault
    exact_threshold: bool = False  # ETC: exact ncx2 quantile per epoch instead of the safe look-up table
    #: the integrity sources that may validate a position (``integrity.sources.LEVELS``); None: the strictest
    #: level the epochs given support (see :func:`tollcli.integrity.sources.level_for`)
    sources: tuple[str, ...] | None = None
    _table: design.EtcThresholdTable | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"RAIM mode {self.mode!r}: use one of {', '.join(MODES)}")
        for name in ("p_md", "p_fa", "p_sat", "p_const"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} = {value}: a probability strictly between 0 and 1")
        if not self.hal_m > 0:
            raise ValueError(f"hal_m = {self.hal_m}: must be positive")

    def etc_threshold(self, dof: np.ndarray, lambda_det: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ETC threshold and its P_FA for each (k, λ_det)."""
        if self.exact_threshold:
            threshold = design.etc_threshold(self.p_md, dof, lambda_det)
            return threshold, design.false_alarm_probability(threshold, dof)
        if self._table is None:
            self._table = design.etc_threshold_table(self.p_md)
        return self._table(dof, lambda_det), self._table.p_fa(dof, lambda_det)


@dataclass
class Detection:
    """Per-epoch results of fault detection (arrays of length E)."""

    dof: np.ndarray
    slope_max_m: np.ndarray
    test_stat: np.ndarray
    threshold: np.ndarray
    lambda_det: np.ndarray
    hpl_m: np.ndarray
    hal_m: np.ndarray
    p_fa: np.ndarray
    status: np.ndarray  # int codes into STATUSES


def detect(geometry: Geometry, test_stat: np.ndarray, params: RaimParams, hal_m=None) -> Detection:
    """Thresholds, protection levels and a status for every epoch.

    ``hal_m`` may be an array (one HAL per epoch, e.g. per candidate geo-object);
    it defaults to ``params.hal_m``.
    """
    n = geometry.dof.shape[0]
    hal = np.broadcast_to(np.asarray(params.hal_m if hal_m is None else hal_m, dtype=float), (n,)).copy()
    dof = geometry.dof
    slope_max = geometry.slope_max_m
    insufficient = (dof < 1) | geometry.singular | (geometry.n_meas == 0)
    k = np.where(insufficient, 0, dof)
    if params.mode == "classic":
        threshold = design.classic_threshold(params.p_fa, k)
        lambda_det = design.classic_lambda_det(params.p_fa, params.p_md, k)
        with np.errstate(invalid="ignore"):
            hpl = slope_max * np.sqrt(lambda_det)
        p_fa = np.where(insufficient, np.nan, params.p_fa)
        unavailable = ~(hpl <= hal)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            lambda_det = np.where(np.isfinite(slope_max) & (slope_max > 0), (hal / slope_max) ** 2, np.nan)
        threshold, p_fa = params.etc_threshold(k, lambda_det)
        hpl = hal.copy()
        unavailable = ~np.isfinite(slope_max) | ~(threshold > 0)
    status = np.full(n, VALID, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        status[test_stat > threshold] = FAULT
    status[np.isnan(test_stat)] = UNMONITORED
    status[unavailable] = UNAVAILABLE
    status[insufficient] = INSUFFICIENT
    nan_if = np.where(insufficient, np.nan, 1.0)
    return Detection(
        dof=np.where(insufficient, np.maximum(dof, 0), dof),
        slope_max_m=slope_max * nan_if,
        test_stat=test_stat,
        threshold=threshold * nan_if,
        lambda_det=lambda_det * nan_if,
        hpl_m=hpl * nan_if,
        hal_m=hal,
        p_fa=p_fa * nan_if,
        status=status,
    )


def status_names(codes: np.ndarray) -> np.ndarray:
    """Int status codes → their names."""
    return np.asarray(STATUSES, dtype=object)[codes]
