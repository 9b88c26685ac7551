"""``tollcli osnma``'s job: a log's Galileo pages through the OSNMA receiver, joined with its epochs.

The keys: the Merkle tree file and public key files given, else those lying beside the log
(``OSNMA_MerkleTree.xml``, ``OSNMA_PublicKey*.xml``, the names the European GNSS Service Centre publishes).
A public key file is used only when the tree file holds its path to the root; without one the receiver
starts cold and takes the key from the signal's DSM-PKR (checked against the same root).

Epochs: a u-blox log's NAV-PVT/NAV-SAT epochs (which satellites the fix used); a page file without epochs
(the ICD test vectors) gets one epoch per subframe with every satellite that sent pages in it.
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


def _log_satellites(log: str, pages: pd.DataFrame) -> pd.DataFrame:
    from tollcli.io.sources import sniff_format

    if sniff_format(log) in ("ubx-nav", "ubx"):
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
                strict: bool = False) -> OsnmaCheck:  # fmt: skip
    """Verify the OSNMA of a log (u-blox or ICD test-vector CSV) and join it with the log's epochs."""
    merkle, public_keys = key_files(log, merkle, public_keys)
    tree = read_merkle_tree(merkle)
    keys = [read_public_key(path, tree) for path in public_keys]
    pages = read_pages(log, strict=strict)
    result = run_osnma(pages.table, OsnmaSettings(tree, keys, sync_bound_s=sync_bound_s))
    status = satellite_status(result, _log_satellites(log, pages.table))
    epochs = epoch_counts(status)
    return OsnmaCheck(result, status, epochs, summarize(log, result, epochs, keys, pages.n_dropped))


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
        "tags_authenticated_by_adkd": {str(k): int(v) for k, v in tags.groupby("adkd").size().items()},
        "data_authenticated": c["data_authenticated"],
        "data_authenticated_by_adkd": {str(k): int(v) for k, v in r.data.groupby("adkd").size().items()},
        "first_authenticated_data_gst": _gst_text(first),
        # as OSNMAlib counts it: the fourth satellite with authenticated ephemeris, at the end of its page
        "first_authenticated_fix_gst": _gst_text(None if fix is None else fix + 2),
        "failures": c["failures"],
        "failures_by_kind": {str(k): int(v) for k, v in r.failures.groupby("kind").size().items()},
        "first_failures": r.failures.head(5).assign(gst=lambda f: [_gst_text(t) for t in f["gst_s"]]).drop(columns="gst_s").to_dict("records"),
        "epochs": n,
        "epochs_with_4_authenticated_used": enough,
        "mean_used_authenticated": round(float(epochs["n_used_authenticated"].mean()), 3) if n else None,
        "mean_galileo_used": round(float(epochs["n_galileo_used"].mean()), 3) if n else None,
    }  # fmt: skip
