"""Integrity sources: every verdict a log supports for an epoch, and the strictest of them.

Sources (``integrity_source``):

===============  =========================================================================
``grs``          the residual test on the receiver's GRS range residuals (exact)
``pseudorange``  the residual test on pseudoranges the tool solved itself (exact)
``gbs``          the receiver's own RAIM (NMEA GBS): a satellite named as failed with a
                 significant bias (|bias|/σ_bias beyond the p_fa quantile, or its missed-detection
                 probability ≤ p_fa) → ``fault_detected``; no verdict where the fix had no
                 redundancy; otherwise HPL = K_H(P_MD)·σ_major of its expected
                 errors, ``valid`` iff HPL ≤ HAL, else ``unavailable``
``gst``          the receiver's error ellipse (NMEA GST): HPL = K_H(P_MD)·σ_major, ``valid``
                 iff HPL ≤ HAL; and the residual test on its RMS field where that is a
                 plausible range RMS (:mod:`tollcli.gnss.receiver_outputs`); the stricter
``model``        the used satellites' geometry and the error model (no fault detection, no receiver estimate):
                 HPL = K_H(P_MD)·σ_major of the WLS covariance under the σ of the environment the residuals
                 measured (urban σ where none did; ``--environment open`` declares open country), or
                 K_H·HDOP·σ_worst where the receiver reports no satellites (:mod:`tollcli.integrity.model_bound`);
                 ``valid`` iff HPL ≤ HAL
``none``         no source gave a verdict
===============  =========================================================================

K_H(P_MD) = √(−2 ln P_MD): the radius that a circular 2-D Gaussian of σ = σ_major exceeds
with probability P_MD (P_MD = 5e-5: 4.45; paper 004's HPL_SBAS = 6.18·d_major is the same
form at its K_H).

Levels (``--integrity-sources``), the sources that may **validate** a position; a denial
(``fault_detected``, ``probable_false_alarm``, ``unavailable``) counts from every source:

==============  ===================================================================
``residual``    residual tests only (``grs``, ``pseudorange``)
``receiver``    and the receiver's own RAIM (``gbs``)
``covariance``  and covariance-only bounds (``gst``)
``model``       and the geometry-and-error-model bound (``model``): what a receiver that reports only
                its satellites (GSA + GSV), or only its HDOP, supports
``auto``        the strictest level the log supports, decided at its first epoch that
                has any source (the default)
==============  ===================================================================

Where several sources give a verdict the strictest wins, in the order ``fault_detected``,
``probable_false_alarm``, ``unavailable``, ``excluded_valid``, ``valid``; every source's
verdict is kept (``residual_status``, ``gbs_status``, ``gst_status``).
"""

from __future__ import annotations

import math

import numpy as np

from tollcli.gnss.receiver_outputs import ReceiverOutputs
from tollcli.integrity.raim import (
    EXCLUDED,
    FAULT,
    PROBABLE_FALSE_ALARM,
    UNAVAILABLE,
    VALID,
)

SOURCES = ("grs", "pseudorange", "gbs", "gst", "model", "none")
RESIDUAL_SOURCES = ("grs", "pseudorange")
LEVELS = {"residual": RESIDUAL_SOURCES, "receiver": (*RESIDUAL_SOURCES, "gbs"),
          "covariance": (*RESIDUAL_SOURCES, "gbs", "gst"), "model": (*RESIDUAL_SOURCES, "gbs", "gst", "model")}  # fmt: skip
LEVEL_CHOICES = ("auto", *LEVELS)
#: what a position vouched for by each source is worth (invoices and the audit quote these)
SOURCE_MEANINGS = {
    "grs": "a residual test on the receiver's own range residuals (GRS): faults are detected at P_MD",
    "pseudorange": "a residual test on the pseudoranges, solved by this tool: faults are detected at P_MD",
    "gbs": "the receiver's own RAIM (GBS): it named no failed satellite with a significant bias and its expected errors bound the position "
    "within the HAL at P_MD (HPL = √(−2 ln P_MD)·σ_major); the fault detection is the receiver's, not re-checked here",
    "gst": "the receiver's error ellipse (GST) bounds the position within the HAL at P_MD (HPL = √(−2 ln P_MD)·σ_major); "
    "a covariance-only bound: it holds for fault-free errors and detects no fault (the audit's P(false charge) bound "
    "counts such positions as possibly misleading)",
    "model": "the geometry of the satellites the receiver used and an error model bound the position within the HAL at "
    "P_MD (HPL = √(−2 ln P_MD)·σ_major; the urban σ unless the residuals measured open sky or --environment open "
    "declared it); the lowest level: no fault detection and no estimate from the receiver — a covariance-only bound "
    "that holds for fault-free errors of the assumed environment (the audit's P(false charge) bound counts such "
    "positions as possibly misleading)",
}
#: sources that detect faults (a position they vouch for is misleading with probability ≤ P_MD even under a fault)
FAULT_DETECTING = ("grs", "pseudorange", "gbs")
#: strictest first; a status not listed gives no verdict
_STRICTNESS = (FAULT, PROBABLE_FALSE_ALARM, UNAVAILABLE, EXCLUDED, VALID)
_NO_VERDICT = len(_STRICTNESS)
NONE = -1  # no verdict from a source


def k_h(p_md: float) -> float:
    """√(−2 ln P_MD): the 2-D Gaussian multiplier of σ_major for a protection level at P_MD."""
    return math.sqrt(-2.0 * math.log(p_md))


def bound_verdict(hpl_m: np.ndarray, hal_m: np.ndarray) -> np.ndarray:
    """``valid`` where HPL ≤ HAL, ``unavailable`` where above, NONE where there is no HPL."""
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(hpl_m), np.where(hpl_m <= hal_m, VALID, UNAVAILABLE), NONE)


def gbs_fault(receiver: ReceiverOutputs, p_fa: float) -> np.ndarray:
    """Whether the satellite a GBS names is a fault, read as the receiver meant it: its bias is significant
    (|bias| / σ_bias beyond the two-sided ``p_fa`` quantile of a Gaussian: 2.81 at 5e-3) or its probability of
    missed detection is at most ``p_fa``; a satellite named with neither figure counts as a fault (the
    receiver said no more)."""
    from statistics import NormalDist

    named = receiver.gbs_failed_svid >= 0
    z = NormalDist().inv_cdf(1.0 - p_fa / 2.0)
    ratio, prob = receiver.gbs_bias_ratio, receiver.gbs_p_md
    with np.errstate(invalid="ignore"):
        significant = (ratio > z) | (prob <= p_fa) | (~np.isfinite(ratio) & ~np.isfinite(prob))
    return named & significant


def receiver_verdicts(receiver: ReceiverOutputs, hal_m: np.ndarray, p_md: float, p_fa: float = 5e-3) -> dict[str, np.ndarray]:
    """HPLs and verdicts of the receiver's own outputs: ``hpl_gbs_m``, ``gbs``, ``hpl_gst_m``, ``gst_bound``.

    GBS: a significant fault (:func:`gbs_fault`) → ``fault_detected``; else its bound; no verdict where the fix
    had no redundancy (the receiver's RAIM could check nothing)."""
    hpl_gbs = k_h(p_md) * receiver.gbs_sigma_major_m
    gbs = np.where(gbs_fault(receiver, p_fa), FAULT, bound_verdict(hpl_gbs, hal_m))
    gbs = np.where(receiver.gbs_redundant, gbs, NONE)
    hpl_gst = k_h(p_md) * receiver.gst_sigma_major_m
    return {"hpl_gbs_m": hpl_gbs, "gbs": gbs, "hpl_gst_m": hpl_gst, "gst_bound": bound_verdict(hpl_gst, hal_m)}


def strictest(*verdicts: np.ndarray) -> np.ndarray:
    """Element-wise the strictest verdict (NONE where none gave one)."""
    rank = np.full(verdicts[0].shape, _NO_VERDICT)
    for v in verdicts:
        rank = np.minimum(rank, _rank(v))
    return np.where(rank < _NO_VERDICT, np.asarray(_STRICTNESS + (NONE,))[rank], NONE)


def _rank(verdict: np.ndarray) -> np.ndarray:
    out = np.full(verdict.shape, _NO_VERDICT)
    for r, status in enumerate(_STRICTNESS):
        out[verdict == status] = r
    return out


def combine(verdicts: dict[str, np.ndarray], allowed: tuple[str, ...], fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(status, deciding source) per epoch: the strictest verdict of ``verdicts`` (source → verdict codes).

    A source outside ``allowed`` cannot validate (its ``valid``/``excluded_valid`` is no verdict);
    its denials count. Where no source decides: ``fallback`` and source ``none``.
    """
    n = fallback.size
    best = np.full(n, _NO_VERDICT)
    source = np.full(n, "none", dtype=object)
    for name, verdict in verdicts.items():  # in SOURCES order: on a tie the earlier source is named
        rank = _rank(verdict)
        if name not in allowed:
            rank = np.where(np.isin(verdict, (VALID, EXCLUDED)), _NO_VERDICT, rank)
        take = rank < best
        best = np.where(take, rank, best)
        source[take] = name
    status = np.where(best < _NO_VERDICT, np.asarray(_STRICTNESS + (0,))[np.minimum(best, _NO_VERDICT)], fallback)
    return status, source


def level_for(has_residual: bool, has_gbs: bool, has_gst: bool, has_model: bool = False) -> str:
    """The strictest level a log supports, from what its first epoch with any source has."""
    if has_residual:
        return "residual"
    if has_gbs:
        return "receiver"
    if has_gst:
        return "covariance"
    return "model" if has_model else "residual"
