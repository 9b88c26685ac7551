"""What a receiver says about its own integrity, per epoch: GBS (its RAIM) and GST (its error ellipse).

* GBS (satellite fault detection): the expected 1σ errors in latitude and longitude (m)
  and the most likely failed satellite (none when the receiver's RAIM found no fault), with its
  probability of missed detection, its estimated bias and the bias's standard deviation: a
  receiver names its *most likely* failed satellite even when the bias is insignificant
  (``gbs_bias_ratio`` = |bias| / σ_bias says how significant; whether it is a fault is the
  integrity sources' call, :func:`tollcli.integrity.sources.gbs_fault`). ``gbs_redundant``: the fix
  had more satellites than unknowns (a 2-D fix more than 3, a 3-D fix more than 4; unknown counts
  count as redundant) — without redundancy a receiver's RAIM checked nothing.
  ``gbs_sigma_major_m`` = the larger of the two σ's (GBS gives no correlation: the
  largest the horizontal σ can be along any axis is at most this, and the bound
  uses it as the major axis).
* GST (pseudorange error statistics): the error ellipse (semi-major, semi-minor axis,
  1σ, m) and the 1σ latitude/longitude errors. ``gst_sigma_major_m`` = the largest
  of the semi-major axis and the two σ's (receivers disagree on which they fill and
  some fill the axis inconsistently: the bound takes the most conservative).
* A σ that is no σ (≤ 0 or infinite: a damaged or hostile sentence, even with a good checksum) makes that output
  give no verdict for its epoch (GBS or GST NaN, and the GST RMS with it): never a bound of zero or less.
* The GST RMS field is meant as the RMS of the range residuals (m). Many receivers
  write something else there (u-blox: 837, 235 111 "m" beside an ellipse of
  2.3 × 3.5 m). It counts as a residual statistic only where it is plausible: a
  range RMS at most ``RMS_RANGE_RATIO_MAX`` times the range σ the ellipse implies
  (σ_major / HDOP; HDOP 1 when unknown). Once one epoch of a log shows an implausible
  value, the receiver's field is ignored for the rest of the log: it is not a range
  RMS on that receiver (``gst_rms_note``: ``implausible`` on the epoch that showed it,
  ``implausible_earlier`` after it; '' where used or absent).
* A GST that contradicts itself is no evidence: its ellipse and its latitude/longitude σ's describe one covariance, so
  major² + minor² = σ_lat² + σ_lon² (the trace). Where both are given and the two sums differ more than
  ``GST_TRACE_RATIO_MAX``-fold (and by more than ``GST_TRACE_SLACK_M2``, the rounding of small values), the sentence
  gives no verdict at all — neither a bound nor a fault (a SkyTraq DGPS receiver writes σ 0.9/0.4 m beside an
  ellipse of 15.1 × 6.6 m and an RMS of 15.9: its "faults" are the sentence's, not the sky's);
  ``gst_rms_note`` ``contradictory``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import pandas as pd

#: a range RMS more than this many times the range σ the ellipse implies is not a range RMS
RMS_RANGE_RATIO_MAX = 10.0
GST_RMS_NOTES = ("", "implausible", "implausible_earlier", "contradictory")
#: a GST whose two traces (major² + minor², σ_lat² + σ_lon²) differ more than this factor contradicts itself ...
GST_TRACE_RATIO_MAX = 4.0
#: ... and by more than this, m² (a σ of 0.1 m written 0.1 or 0.2 doubles its square)
GST_TRACE_SLACK_M2 = 1.0
#: what each note tells an auditor (the integrity summary and the invoice quote it)
GST_RMS_NOTE_MEANINGS = {
    "implausible": "the GST RMS field is more than {ratio:g}× the range σ its own error ellipse implies: not a "
    "range-residual RMS; ignored (neither validates nor faults the epoch)",
    "implausible_earlier": "an earlier epoch showed this receiver's GST RMS field is not a range-residual RMS: ignored",
    "contradictory": "the GST sentence contradicts itself (its error ellipse and its latitude/longitude σ's are not one "
    "covariance: major² + minor² differs from σ_lat² + σ_lon² more than {trace:g}-fold): no evidence, neither a bound nor a fault",
}


def gst_contradicts(major_m: np.ndarray, minor_m: np.ndarray, sigma_lat_m: np.ndarray, sigma_lon_m: np.ndarray) -> np.ndarray:
    """Per epoch: the GST's ellipse and its σ's are given and are not one covariance (their traces differ more than
    ``GST_TRACE_RATIO_MAX``-fold and by more than ``GST_TRACE_SLACK_M2``); False where either is not given."""
    with np.errstate(invalid="ignore", over="ignore"):
        a = major_m**2 + minor_m**2
        b = sigma_lat_m**2 + sigma_lon_m**2
        given = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return given & (hi > GST_TRACE_RATIO_MAX * lo) & (hi - lo > GST_TRACE_SLACK_M2)


@dataclass
class ReceiverOutputs:
    """Per-epoch arrays (E,) of the receiver's own integrity outputs (NaN / -1 where absent)."""

    gbs_sigma_major_m: np.ndarray
    gbs_failed_svid: np.ndarray
    gbs_bias_ratio: np.ndarray  # |bias| / its σ of the satellite GBS names (NaN: not given)
    gbs_p_md: np.ndarray  # GBS probability of missed detection of that satellite (NaN: not given)
    gbs_redundant: np.ndarray  # bool: the fix had more satellites than unknowns
    gst_sigma_major_m: np.ndarray
    gst_rms_m: np.ndarray  # the RMS where it counts as a residual statistic, else NaN
    gst_rms_note: np.ndarray  # codes into GST_RMS_NOTES
    hdop: np.ndarray | None = None  # the receiver's HDOP (GSA, GGA, NAV-DOP; NaN where not given)

    def take(self, rows: np.ndarray) -> ReceiverOutputs:
        return ReceiverOutputs(**{f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[rows] for f in fields(self)})


class RmsCarry:
    """Across the chunks of one log: the line of the first epoch whose GST RMS was implausible (-1: none yet)."""

    def __init__(self) -> None:
        self.implausible_line = -1


def _column(epochs: pd.DataFrame, name: str) -> np.ndarray:
    return epochs[name].to_numpy(float) if name in epochs else np.full(len(epochs), np.nan)


def _largest(*arrays: np.ndarray) -> np.ndarray:
    """Element-wise the largest finite value (NaN where none is)."""
    stack = np.stack(arrays)
    with np.errstate(invalid="ignore"):
        out = np.nanmax(np.where(np.isfinite(stack), stack, -np.inf), axis=0)
    return np.where(np.isfinite(out), out, np.nan)


def _impossible(*arrays: np.ndarray) -> np.ndarray:
    """Element-wise: some σ given is not a σ (≤ 0, or infinite): the receiver's output that carries it says nothing."""
    stack = np.stack(arrays)
    with np.errstate(invalid="ignore"):
        return ((stack <= 0) | np.isinf(stack)).any(axis=0)


def rms_plausible(rms_m: np.ndarray, sigma_major_m: np.ndarray, hdop: np.ndarray) -> np.ndarray:
    """Whether each GST RMS can be a range-residual RMS given the ellipse and the geometry (False where unknown)."""
    h = np.where(np.isfinite(hdop) & (hdop > 0), hdop, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.isfinite(rms_m) & (rms_m >= 0) & (rms_m <= RMS_RANGE_RATIO_MAX * sigma_major_m / h)


def receiver_outputs(epochs: pd.DataFrame, carry: RmsCarry | None = None) -> ReceiverOutputs:
    """The GBS and GST integrity outputs of every row of ``epochs`` (``carry``: the log's earlier chunks)."""
    n = len(epochs)
    gbs_sigmas = (_column(epochs, "gbs_err_lat_m"), _column(epochs, "gbs_err_lon_m"))
    gbs = np.where(_impossible(*gbs_sigmas), np.nan, _largest(*gbs_sigmas))  # a σ ≤ 0 is no bound: no GBS verdict
    failed = epochs["gbs_failed_svid"].to_numpy(np.int64) if "gbs_failed_svid" in epochs else np.full(n, -1, np.int64)
    bias, bias_sd = _column(epochs, "gbs_bias_m"), _column(epochs, "gbs_bias_sd_m")
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(bias_sd > 0, np.abs(bias) / np.where(bias_sd > 0, bias_sd, 1.0), np.nan)
    n_used = _column(epochs, "n_used")
    mode = _column(epochs, "fix_mode")
    unknowns = np.where(mode == 2, 3, 4)
    redundant = ~(np.isfinite(n_used) & (n_used > 0) & (n_used <= unknowns))
    gst_sigmas = (_column(epochs, "sigma_major_m"), _column(epochs, "sigma_lat_m"), _column(epochs, "sigma_lon_m"))
    contradictory = gst_contradicts(gst_sigmas[0], _column(epochs, "sigma_minor_m"), gst_sigmas[1], gst_sigmas[2])
    gst_impossible = _impossible(*gst_sigmas) | contradictory  # no bound, and no RMS to fault with, from such a GST
    gst = np.where(gst_impossible, np.nan, _largest(*gst_sigmas))  # a σ ≤ 0 is no bound: no GST verdict that epoch
    rms = np.where(gst_impossible, np.nan, _column(epochs, "rms_residual_m"))
    given = np.isfinite(rms)
    bad = given & ~rms_plausible(rms, gst, _column(epochs, "hdop"))
    note = np.where(bad, 1, 0)
    earlier = np.zeros(n, bool)
    carry = carry if carry is not None else RmsCarry()
    if carry.implausible_line >= 0:
        earlier[:] = True
    elif bad.any():
        first = int(np.argmax(bad))
        earlier[first + 1 :] = True
        carry.implausible_line = int(epochs["line"].iat[first]) if "line" in epochs else first
    note = np.where(given & earlier & ~bad, 2, note)
    note = np.where(contradictory, 3, note)
    used = given & (note == 0)
    return ReceiverOutputs(gbs, failed, ratio, _column(epochs, "gbs_p_md"), redundant, gst, np.where(used, rms, np.nan),
                           note.astype(np.int8), _column(epochs, "hdop"))  # fmt: skip
