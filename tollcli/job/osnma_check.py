"""``tollcli osnma``'s job: a log's Galileo pages through the OSNMA receiver, joined with its epochs.

The keys: the Merkle tree file and public key files given, else those lying beside the log
(``OSNMA_MerkleTree.xml``, ``OSNMA_PublicKey*.xml``, the names the European GNSS Service Centre publishes).
A public key file is used only when the tree file holds its path to the root; without one the receiver
starts cold and takes the key from the signal's DSM-PKR (checked against the same root).

Epochs: a u-blox log's NAV-PVT/NAV-SAT epochs (which satellites the fix used), with the position from the
satellites with authenticated data alone and its distance to the fix (:func:`authenticated_fixes`); a page file
without epochs (the ICD test vectors) gets one epoch per subframe with every satellite that sent pages in it.
"""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import UsageError
from tollcli.gnss.osnma.dsm import read_merkle_tree, read_public_key
from tollcli.gnss.osnma.pages import read_pages
from tollcli.gnss.osnma.receiver import OsnmaResult, OsnmaSettings, run_osnma
from tollcli.gnss.osnma.satellite_status import GST_ORIGIN_GPS_S, epoch_counts, satellite_status
from tollcli.gnss.osnma.tesla import WEEK_S
from tollcli.geoobjects.geojson_stream import gc_paused


@dataclass
class OsnmaCheck:
    result: OsnmaResult
    satellites: pd.DataFrame  # per epoch and satellite, with nav_authenticated
    epochs: pd.DataFrame  # per epoch counts
    summary: dict


def key_files(log: str, merkle: str | None, public_keys: list[str] | None) -> tuple[str, list[str]]:
    """The Merkle tree file and public key files to use (given, else beside the log)."""
    folder = os.path.dirname(os.path.abspath(log))
    if merkle is None:
        merkle = os.path.join(folder, "OSNMA_MerkleTree.xml")
        if not os.path.exists(merkle):
            raise UsageError(f"{log}: no OSNMA Merkle tree given (--merkle) and no OSNMA_MerkleTree.xml beside the log")
    if public_keys is None:
        public_keys = sorted(glob.glob(os.path.join(folder, "OSNMA_PublicKey*.xml")))
    return merkle, public_keys


#: an empty per-epoch satellite table (a check without per-epoch tables)
NO_SATELLITES = pd.DataFrame({"epoch": np.zeros(0, np.int64), "time_utc": pd.to_datetime([], utc=True), "constellation": np.zeros(0, object),
                              "svid": np.zeros(0, np.int64), "used": np.zeros(0, bool)})  # fmt: skip


def _log_satellites(log: str, pages: pd.DataFrame, kind: str | None = None) -> pd.DataFrame:
    from tollcli.io.sources import sniff_format

    if (kind or sniff_format(log)) in ("ubx-nav", "ubx"):
        from tollcli.readers.ubx_nav import iter_ubx_nav_tables

        chunks = [t.satellites for t in iter_ubx_nav_tables(log)]
        if chunks and sum(len(c) for c in chunks):
            return pd.concat(chunks, ignore_index=True)
    gst = pages["wn"].to_numpy(np.int64) * WEEK_S + pages["tow_s"].to_numpy(np.int64)
    frame = pd.DataFrame({"sf": gst - gst % 30 + 30, "svid": pages["svid"].to_numpy(np.int64)}).drop_duplicates().sort_values(["sf", "svid"])
    leap = 18  # the ICD test vectors are of 2023
    time_utc = pd.to_datetime((frame["sf"].to_numpy() + GST_ORIGIN_GPS_S - leap) * 1e9 + pd.Timestamp("1980-01-06").value, utc=True)
    return pd.DataFrame({"epoch": pd.factorize(frame["sf"])[0], "time_utc": time_utc, "constellation": "Galileo",
                         "svid": frame["svid"].to_numpy(), "used": True})  # fmt: skip


def check_osnma(log: str, merkle: str | None = None, public_keys: list[str] | None = None, sync_bound_s: float = 30.0,
                strict: bool = False, p_fa: float = 5e-3, positions: bool = True, data: str | None = None,
                kind: str | None = None, per_epoch: bool = True) -> OsnmaCheck:  # fmt: skip
    """Verify the OSNMA of a log (u-blox or ICD test-vector CSV) and join it with the log's epochs
    (``positions``: with the authenticated satellites' own position per epoch, :func:`authenticated_fixes`).
    ``data``: where the log's bytes are read (a :class:`~tollcli.io.log_run.LogRun`'s replay; default the log), ``kind``
    its format when known. ``per_epoch`` False: no per-epoch tables (``satellites``/``epochs`` empty) — a charge
    joins the verification with its own chunks' satellites (:meth:`~tollcli.job.osnma_evidence.OsnmaEvidence.authenticated_for`)
    instead of reading the log's satellites a second time."""
    merkle, public_keys = key_files(log, merkle, public_keys)
    tree = read_merkle_tree(merkle)
    keys = [read_public_key(path, tree) for path in public_keys]
    data = data or log
    with gc_paused():  # tens of thousands of pages and receiver records, no cycles: no collections over them
        pages = read_pages(data, strict=strict)
        result = run_osnma(pages.table, OsnmaSettings(tree, keys, sync_bound_s=sync_bound_s))
    sats = _log_satellites(data, pages.table, kind) if per_epoch else NO_SATELLITES
    status = satellite_status(result, sats)
    epochs = epoch_counts(status)
    positions = authenticated_fixes(data, status, p_fa, kind) if positions and len(status) else None
    if positions is not None:
        epochs = epochs.merge(positions.drop(columns=["n_used_slots", "n_used_authenticated"]), on="time_utc", how="left")
    summary = summarize(log, result, epochs, keys, pages.n_dropped)
    if positions is not None:
        summary.update(position_summary(epochs))
    return OsnmaCheck(result, status, epochs, summary)


def authenticated_fixes(log: str, status: pd.DataFrame, p_fa: float = 5e-3, kind: str | None = None) -> pd.DataFrame | None:
    """Per epoch of a u-blox log: the receiver's fix, the position from the satellites with authenticated data
    alone and its distance to the fix (:func:`tollcli.integrity.nav_authentication.authenticated_positions`);
    None for a page file without fixes."""
    from tollcli.io.sources import sniff_format

    if (kind or sniff_format(log)) not in ("ubx-nav", "ubx"):
        return None
    from tollcli.gnss.nmea_measurements import AngleCarry, nmea_measurements
    from tollcli.integrity.nav_authentication import authenticated_satellites, epoch_authentication
    from tollcli.readers.ubx_nav import iter_ubx_nav_tables

    auth = authenticated_satellites(status)
    carry, parts = AngleCarry(), []
    for chunk in iter_ubx_nav_tables(log):
        e = chunk.epochs
        if e.empty:
            continue
        fixes = epoch_authentication(nmea_measurements(e, chunk.satellites, carry=carry), e, auth, p_fa)
        parts.append(pd.concat([e[["time_utc", "lat_deg", "lon_deg"]].reset_index(drop=True), fixes], axis=1))
    return pd.concat(parts, ignore_index=True).drop_duplicates("time_utc") if parts else None


def position_summary(epochs: pd.DataFrame) -> dict:
    """How often the position from authenticated satellites alone existed, and how far it was from the fix."""
    sep = epochs["auth_sep_m"].to_numpy(float)
    partial = np.isfinite(sep) & (epochs["nav_auth"].to_numpy(object) != "authenticated")
    ratio = sep[partial] / epochs["auth_sep_threshold_m"].to_numpy(float)[partial]
    q = (lambda v, p: round(float(np.percentile(v, p)), 3) if v.size else None)  # noqa: E731
    return {"nav_auth_epochs": {str(k): int(v) for k, v in epochs["nav_auth"].value_counts().sort_index().items()},
            "auth_sep_m_subset": {"epochs": int(partial.sum()), "median": q(sep[partial], 50), "p95": q(sep[partial], 95),
                                  "max": q(sep[partial], 100), "max_over_threshold": q(ratio, 100)}}  # fmt: skip


def _gst_text(gst_s) -> str | None:
    if gst_s is None or (isinstance(gst_s, float) and np.isnan(gst_s)):
        return None
    wn, tow = divmod(int(gst_s), WEEK_S)
    return f"WN {wn} TOW {tow}"


def summarize(log: str, r: OsnmaResult, epochs: pd.DataFrame, keys, dropped: int) -> dict:
    c = r.counts
    tags = r.tags[r.tags["verified"]]
    first = r.data["at_s"].min() if len(r.data) else None
    fix = c["first_authenticated_fix_s"]
    n = len(epochs)
    enough = int((epochs["n_used_authenticated"] >= 4).sum()) if n else 0
    return {
        "file": log,
        "pages": c["pages"], "pages_without_time": dropped, "crc_failed": c["crc_failed"], "broken_hkroot": c["broken_hkroot"],
        "public_keys": {str(k.pkid): ("verified against the Merkle tree" if k.verified else "not on the Merkle tree: unused") for k in keys},
        "state": c["state"],
        "kroots_authenticated": c["kroots_authenticated"],
        "tesla_keys_verified": int(r.keys["verified"].sum()) if len(r.keys) else 0,
        "tags_authenticated": c["tags_authenticated"],
        "tags_authenticated_by_adkd": _counts(tags, "adkd"),
        "data_authenticated": c["data_authenticated"],
        "data_authenticated_by_adkd": _counts(r.data, "adkd"),
        "first_authenticated_data_gst": _gst_text(first),
        # as OSNMAlib counts it: the fourth satellite with authenticated ephemeris, at the end of its page
        "first_authenticated_fix_gst": _gst_text(None if fix is None else fix + 2),
        "failures": c["failures"],
        "failures_by_kind": _counts(r.failures, "kind"),
        "first_failures": (r.failures.head(5).assign(gst=lambda f: [_gst_text(t) for t in f["gst_s"]]).drop(columns="gst_s").to_dict("records")
                           if len(r.failures) and "gst_s" in r.failures else []),  # fmt: skip
        "epochs": n,
        "epochs_with_4_authenticated_used": enough,
        "mean_used_authenticated": round(float(epochs["n_used_authenticated"].mean()), 3) if n else None,
        "mean_galileo_used": round(float(epochs["n_galileo_used"].mean()), 3) if n else None,
    }  # fmt: skip


def _counts(table, column: str) -> dict[str, int]:
    """Rows per value of ``column`` ({} for a table without rows, which may have no columns either)."""
    if table is None or len(table) == 0 or column not in table:
        return {}
    return {str(k): int(v) for k, v in table.groupby(column).size().items()}
