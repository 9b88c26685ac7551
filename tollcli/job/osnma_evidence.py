"""OSNMA as evidence of a charge: which satellites' data were authenticated when, the invoice's record of it,
and its failures as findings (used by ``process``, ``findings`` and ``verify``).

A log is checked when it is a u-blox log carrying Galileo I/NAV pages (RXM-SFRBX) and the OSNMA Merkle tree
is given or lies beside the log (``OSNMA_MerkleTree.xml``: :func:`tollcli.job.osnma_check.key_files`). Every
other log has no OSNMA evidence: its invoice records none, unless authentication is required, when each
position is ``unauthenticated`` (:mod:`tollcli.integrity.nav_authentication`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.charging.invoice import file_sha256
from tollcli.enforcement.osnma_failures import osnma_failure_findings
from tollcli.errors import UsageError
from tollcli.integrity.nav_authentication import ACCEPTED, NAV_AUTH_STATUSES, STATUS_NOTES, authenticated_satellites
from tollcli.io.columns import Columns
from tollcli.io.sources import printable_path
from tollcli.readers.gps_time import LEAP_SECONDS

#: log kinds whose files may carry Galileo I/NAV pages
PAGE_KINDS = ("ubx-nav", "ubx")
#: the time-synchronisation bound a charge's OSNMA check assumes, s (the receiver guidelines' 30 s: every tag used)
SYNC_BOUND_S = 30.0


@dataclass
class OsnmaEvidence:
    """A log's OSNMA check, the satellites it authenticated per epoch, and the key files it used.

    ``pending``: the check still running beside the charge (a forked process); :attr:`check` waits for it."""

    pending: object  # tollcli.job.osnma_check.OsnmaCheck, or a ForkedWork making one
    merkle: str
    public_keys: list[str]

    @property
    def check(self):
        from tollcli.job.forked_work import ForkedWork

        if isinstance(self.pending, ForkedWork):
            self.pending = self.pending.result()
        return self.pending

    def authenticated_for(self, satellites: pd.DataFrame | Columns) -> pd.DataFrame:
        """(``time_utc``, ``sv``) of the rows of a chunk's satellite table (``time_utc``, ``constellation``, ``svid``)
        whose navigation data were authenticated by then: what the chunk's positions look up."""
        from tollcli.gnss.osnma.satellite_status import satellite_status

        if isinstance(satellites, Columns):  # (the NMEA reader's columns)
            satellites = Columns({c: satellites.held(c) for c in ("time_utc", "constellation", "svid")}).to_pandas()
        return authenticated_satellites(satellite_status(self.check.result, satellites[["time_utc", "constellation", "svid"]]))

    @property
    def failure_times(self) -> pd.Series:
        """UTC times of the check's failures."""
        return gst_to_utc(self.check.result.failures["gst_s"])


def osnma_evidence(log: str, kind: str, merkle: str | None = None, public_keys: list[str] | None = None,
                   auto: bool = True, required: bool = False, strict: bool = False, run=None) -> OsnmaEvidence | None:  # fmt: skip
    """The log's OSNMA evidence, or None when it has none (module docstring).

    ``merkle`` given: the log must carry pages (UsageError otherwise). ``auto``: look for the tree beside the
    log. ``required`` (--require-authenticated) on a u-blox log without a tree anywhere: UsageError. ``run``: the
    log's :class:`~tollcli.io.log_run.LogRun` (the pages are read from its replay, the log is not opened again; a log
    on stdin is checked with the key files given).
    """
    if kind not in PAGE_KINDS or (log == "-" and (run is None or merkle is None)):
        if merkle is not None:
            raise UsageError(f"{log}: --osnma-merkle needs a u-blox log file with Galileo I/NAV pages (RXM-SFRBX)")
        return None
    from tollcli.job.osnma_check import check_osnma, key_files  # (here: a log without pages never imports the check)

    if merkle is None:
        beside = os.path.join(os.path.dirname(os.path.abspath(log)), "OSNMA_MerkleTree.xml")
        if not (auto and os.path.exists(beside)):
            if required:
                raise UsageError(f"{log}: --require-authenticated needs the OSNMA Merkle tree (--osnma-merkle; "
                                 "or OSNMA_MerkleTree.xml beside the log)")  # fmt: skip
            return None
    merkle, public_keys = key_files(log, merkle, public_keys if public_keys is not None or log != "-" else [])
    if run is None:
        check = check_osnma(log, merkle, public_keys, SYNC_BOUND_S, strict, positions=False, per_epoch=False)
    else:
        with run.named_errors():
            replay = run.replay_path()
        check = _beside(run, lambda: check_osnma(log, merkle, public_keys, SYNC_BOUND_S, strict, positions=False, data=replay,
                                                 kind=kind, per_epoch=False))  # the charge joins it with its own chunks' satellites
    return OsnmaEvidence(check, merkle, public_keys)


def _beside(run, work):
    """``work`` (the OSNMA verification: pure Python, its own input) run in a forked process beside the charge's own
    reading, on another CPU (:class:`~tollcli.job.forked_work.ForkedWork`); its result is waited for when the first
    chunk needs it. Inline where no second CPU or no child process is to be had (a batch's pool worker). Errors name
    the log."""
    import multiprocessing

    from tollcli.job.forked_work import ForkedWork

    def named():
        with run.named_errors():
            return work()

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cpus < 2 or multiprocessing.current_process().daemon or not hasattr(os, "fork"):
        return named()
    return ForkedWork(named)


def inputs_record(evidence: OsnmaEvidence) -> dict:
    """The invoice's ``inputs`` entries for the key files (paths and SHA-256, for ``verify``)."""
    return {"osnma_merkle": printable_path(evidence.merkle), "osnma_merkle_sha256": file_sha256(evidence.merkle),
            "osnma_public_keys": [printable_path(p) for p in evidence.public_keys],
            "osnma_public_keys_sha256": [file_sha256(p) for p in evidence.public_keys]}  # fmt: skip


def gst_to_utc(gst_s) -> pd.Series:
    """GST seconds (since the GST origin) → UTC timestamps (leap seconds removed)."""
    from tollcli.gnss.osnma.satellite_status import GST_ORIGIN_GPS_S

    gps_s = np.asarray(gst_s, float) + GST_ORIGIN_GPS_S
    t = np.datetime64("1980-01-06T00:00:00", "ns") + (gps_s * 1e9).astype("timedelta64[ns]")
    leap = np.zeros(len(t), dtype=np.int64)
    for date, seconds in LEAP_SECONDS:  # GPS time is ahead of UTC by the leap seconds since 1980 in force then
        leap = np.where(t - np.timedelta64(seconds, "s") >= np.datetime64(date, "ns"), seconds, leap)
    return pd.Series(pd.to_datetime(t - leap.astype("timedelta64[s]"), utc=True))


def fixes_before(epochs: pd.DataFrame, times_utc: pd.Series) -> pd.DataFrame:
    """The rows (``time_utc``, ``lat_deg``, ``lon_deg``) of ``epochs`` that are the last fix at or before one of
    ``times_utc``: all a finding at those times needs, kept chunk by chunk."""
    cols = ["time_utc", "lat_deg", "lon_deg"]
    fx = epochs[cols].dropna()
    if fx.empty or not len(times_utc):
        return fx.iloc[:0]
    t = pd.to_datetime(fx["time_utc"], utc=True).dt.tz_convert(None).to_numpy("datetime64[ns]")
    order = np.argsort(t, kind="stable")
    want = pd.to_datetime(pd.Series(times_utc), utc=True).dt.tz_convert(None).to_numpy("datetime64[ns]")
    at = np.searchsorted(t[order], want, side="right") - 1
    return fx.iloc[order[np.unique(at[at >= 0])]].reset_index(drop=True)


def failure_findings(evidence: OsnmaEvidence | None, fixes: pd.DataFrame) -> list[dict]:
    """The check's failures as ``osnma_failure`` findings, placed at the fix at or before each (``fixes``:
    ``time_utc``, ``lat_deg``, ``lon_deg``)."""
    if evidence is None or not len(evidence.check.result.failures):
        return []
    failures = evidence.check.result.failures
    return osnma_failure_findings(failures.assign(time_utc=gst_to_utc(failures["gst_s"]).to_numpy()), fixes)


def line_qualifier(evidence_items: list[dict]) -> dict:
    """Whether a charge's positions rest on authenticated navigation data: the count of its evidence positions
    per ``nav_auth`` and one word for them all — ``authenticated`` (every position's fix used only satellites
    with authenticated data), ``corroborated`` (every position accepted, some through the authenticated
    satellites' own position), ``partly``, ``unauthenticated``, ``no_positions``."""
    counts: dict[str, int] = {}
    for item in evidence_items:
        status = item.get("nav_auth", "not_checked")
        counts[status] = counts.get(status, 0) + 1
    n = sum(counts.values())
    accepted = sum(counts.get(s, 0) for s in ACCEPTED)
    if n == 0:
        word = "no_positions"
    elif counts.get("authenticated", 0) == n:
        word = "authenticated"
    elif accepted == n:
        word = "corroborated"
    elif accepted:
        word = "partly"
    else:
        word = "unauthenticated"
    return {"qualifier": word, "positions": dict(sorted(counts.items()))}


def record_in_invoice(invoice: dict, evidence: OsnmaEvidence | None, epoch_counts: dict[str, int], required: bool) -> None:
    """Each line's and each passage not charged's ``navigation_authentication``, the invoice's summary of the check,
    and the notes of the statuses a required authentication failed."""
    for passage in (*invoice["lines"], *invoice["not_charged"]):
        passage["navigation_authentication"] = line_qualifier(passage.get("evidence") or [])
    block = {"method": "Galileo OSNMA (navigation message authentication)", "required": required,
             "epochs": {k: int(epoch_counts.get(k, 0)) for k in NAV_AUTH_STATUSES if epoch_counts.get(k)}}  # fmt: skip
    if evidence is None:
        block["checked"] = "no: the log carries no Galileo I/NAV pages to authenticate"
    else:
        s = evidence.check.summary
        block.update(checked="yes", sync_bound_s=SYNC_BOUND_S,
                     public_keys=s["public_keys"], kroots_authenticated=s["kroots_authenticated"],
                     tags_authenticated=s["tags_authenticated"], data_authenticated=s["data_authenticated"],
                     first_authenticated_fix_gst=s["first_authenticated_fix_gst"], failures=s["failures"],
                     failures_by_kind=s["failures_by_kind"])  # fmt: skip
    invoice["navigation_authentication"] = block
    if required:
        seen = {status for p in (*invoice["lines"], *invoice["not_charged"]) for status in p["statuses"]}
        notes = {k: v for k, v in STATUS_NOTES.items() if k in seen}
        if notes:
            invoice["status_notes"] = {**(invoice.get("status_notes") or {}), **notes}


def key_paths_from_inputs(inputs: dict) -> tuple[str | None, list[str] | None]:
    """The key files an invoice names (None, None: it was made without OSNMA evidence)."""
    merkle = inputs.get("osnma_merkle")
    return (merkle if isinstance(merkle, str) else None), (list(inputs.get("osnma_public_keys") or []) if merkle else None)
