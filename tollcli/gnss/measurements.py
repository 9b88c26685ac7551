"""The padded per-epoch measurement arrays the RAIM works on.

One row per epoch, one slot per measurement (satellite or satellite-signal),
padded to the epoch with the most; ``mask`` says which slots are real. Input
adapters (NMEA, GSDC derived, RINEX) all produce a :class:`Measurements`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from tollcli.gnss.receiver_outputs import ReceiverOutputs

CONSTELLATION_LETTER = {
    "GPS": "G", "GLONASS": "R", "Galileo": "E", "BeiDou": "C", "QZSS": "J", "NavIC": "I", "SBAS": "S", "unknown": "X",
}  # fmt: skip


@dataclass
class Measurements:
    """Padded arrays (E epochs × N slots) plus what the RAIM needs per epoch."""

    H: np.ndarray  # (E, N, 3 + C): [−e, −n, −u, clock one-hot]
    sigma_m: np.ndarray  # (E, N)
    mask: np.ndarray  # (E, N)
    sv: np.ndarray  # (E, N) labels, e.g. "G05" or "E11 E5a" ('' for empty slots)
    residual_m: np.ndarray | None = None  # (E, N) post-fit residuals (NMEA GRS), or
    dy_m: np.ndarray | None = None  # (E, N) pre-fit residuals at the linearisation point (pseudoranges)
    test_stat_override: np.ndarray | None = None  # (E,) a statistic from elsewhere (GST approximation), NaN = none
    test_stat_source: np.ndarray | None = None  # (E,) 'grs', 'gst' (a plausible GST RMS), 'pseudorange', 'none'
    satellites_reported: np.ndarray | None = None  # (E,) the receiver reported its satellites (NMEA GSA/GSV); None: n/a
    receiver: ReceiverOutputs | None = None  # the receiver's own integrity outputs (NMEA GBS, GST)
    cn0_dbhz: np.ndarray | None = None  # (E, N) carrier-to-noise density of each measurement (NaN: not reported)
    #: (E, N) the σ the ``model`` bound uses: the σ of the environment the residuals measured, the urban σ where
    #: they measured none (:func:`tollcli.integrity.environment.with_environment`); None: not set (urban σ)
    model_sigma_m: np.ndarray | None = None
    model_open: np.ndarray | None = None  # (E,) bool: the model bound may take open sky (measured, or declared)
    env_measured: np.ndarray | None = None  # (E,) bool: the residuals measured the epoch's environment (open or urban)
    #: (E,) bool: the receiver says the fix is corrected (GGA quality 2 DGNSS/SBAS, 4 RTK fixed, 5 RTK float, 9 SBAS;
    #: u-blox diffSoln/carrSoln; gpsd DGPS/RTK): its σ is the corrected one, at the ``model`` level too
    corrected_fix: np.ndarray | None = None
    #: pseudorange logs: each measurement's satellite (E, N, 3; ECEF at transmission, in the ECEF frame of that time),
    #: its pseudorange with the satellite clock and the atmosphere removed (E, N; m) and its receiver-clock group
    #: (E, N; one per constellation): what the trajectory estimator (:mod:`tollcli.integrity.trajectory`) solves from
    sat_ecef_m: np.ndarray | None = None
    pr_m: np.ndarray | None = None
    clock_index: np.ndarray | None = None
    #: (E,) the trajectory estimator's verdict inputs where it placed the epochs (``--positioning smoothed|filtered``):
    #: which positioning, its HPL (m), fault test statistic and degrees of freedom, and the measurements its robust
    #: loss set aside; None: snapshot positions (the RAIM decides)
    trajectory_source: np.ndarray | None = None
    trajectory_hpl_m: np.ndarray | None = None
    trajectory_test_stat: np.ndarray | None = None
    trajectory_dof: np.ndarray | None = None
    trajectory_set_aside: np.ndarray | None = None
    trajectory_lost: np.ndarray | None = None  # epochs near where a pass of the estimator lost the vehicle

    def take(self, rows: np.ndarray) -> Measurements:
        """The given epochs (rows may repeat: one per epoch and geo-object)."""
        return Measurements(**{f.name: None if getattr(self, f.name) is None else (
            getattr(self, f.name).take(rows) if f.name == "receiver" else getattr(self, f.name)[rows]) for f in fields(self)})


def slots(epoch_row: np.ndarray, n_epochs: int) -> tuple[np.ndarray, int]:
    """Slot index of each (sorted-by-epoch) measurement row, and the slot count N."""
    if epoch_row.size == 0:
        return np.zeros(0, dtype=np.int64), 0
    starts = np.searchsorted(epoch_row, np.arange(n_epochs))
    slot = np.arange(epoch_row.size) - starts[epoch_row]
    return slot, int(slot.max()) + 1


def pad(values: np.ndarray, epoch_row: np.ndarray, slot: np.ndarray, shape: tuple[int, int], fill) -> np.ndarray:
    """Scatter per-measurement ``values`` into an (E, N) array."""
    out = np.full(shape, fill, dtype=np.asarray(values).dtype if values.dtype != object else object)
    out[epoch_row, slot] = values
    return out


def sv_labels(constellation: np.ndarray, svid: np.ndarray) -> np.ndarray:
    """RINEX-style satellite names: ('GPS', 5) → 'G05' (each distinct satellite formatted once).

    ``constellation``: names, or a ``pandas.Categorical`` of them (without missing values).
    """
    import pandas as pd

    svid = np.asarray(svid).astype(np.int64)
    if len(constellation) == 0:
        return np.empty(0, dtype=object)
    if hasattr(constellation, "categories"):  # a pandas.Categorical: already coded
        codes, names = np.asarray(constellation.codes), list(constellation.categories)
    else:
        codes, names = pd.factorize(np.asarray(constellation, dtype=object), use_na_sentinel=False)
    key = codes.astype(np.int64) * 1_000_000 + svid
    uniq, inverse = np.unique(key, return_inverse=True)
    labels = np.array([f"{CONSTELLATION_LETTER.get(names[k // 1_000_000], 'X')}{k % 1_000_000:02d}" for k in uniq.tolist()],
                      dtype=object)  # fmt: skip
    return labels[inverse.reshape(-1)]
