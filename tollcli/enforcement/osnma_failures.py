"""``osnma_failure`` findings (category spoofing): what Galileo OSNMA refused, by satellite and time.

A failed MAC tag (navigation data that are not the ones the satellite signed: forged, or replayed from
another time), a TESLA key that does not hash to the verified chain, a MACSEQ that does not verify, or a root
key / public key whose signature or Merkle path is wrong. Failures of one satellite and one kind less than
``GROUP_S`` apart are one finding (a forged ephemeris fails every tag over it until it changes); its evidence
names the satellite, the kind, how many failed, the Galileo system time of the first and its detail.
Kinds of the whole chain (root key, public key, MAC look-up table) name satellite ``E00``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.enforcement.findings import _finding

#: failures of one satellite and kind this close (s) are one finding
GROUP_S = 300.0


def osnma_failure_findings(failures: pd.DataFrame, fixes: pd.DataFrame) -> list[dict]:
    """Findings from ``failures`` (``time_utc``, ``svid``, ``kind``, ``detail``; ``gst_s`` optional) placed at the
    fix at or before each finding's start (``fixes``: ``time_utc``, ``lat_deg``, ``lon_deg``; NaN before any)."""
    if failures.empty:
        return []
    f = failures.assign(t_s=pd.to_datetime(failures["time_utc"], utc=True).dt.tz_convert(None)
                        .to_numpy("datetime64[ms]").astype(np.int64) / 1000.0)  # fmt: skip
    f = f.sort_values(["svid", "kind", "t_s"], kind="stable").reset_index(drop=True)
    same = (f["svid"].to_numpy()[1:] == f["svid"].to_numpy()[:-1]) & (f["kind"].to_numpy()[1:] == f["kind"].to_numpy()[:-1])
    new = np.r_[True, ~same | (np.diff(f["t_s"].to_numpy()) > GROUP_S)]
    group = np.cumsum(new) - 1
    fx = fixes[["time_utc", "lat_deg", "lon_deg"]].dropna()
    fx_t = pd.to_datetime(fx["time_utc"], utc=True).dt.tz_convert(None).to_numpy("datetime64[ms]").astype(np.int64) / 1000.0
    order = np.argsort(fx_t, kind="stable")
    fx_t, lat, lon = fx_t[order], fx["lat_deg"].to_numpy(float)[order], fx["lon_deg"].to_numpy(float)[order]
    out = []
    for g in range(int(group[-1]) + 1 if len(group) else 0):
        rows = f[group == g]
        t0, t1 = float(rows["t_s"].iat[0]), float(rows["t_s"].iat[-1])
        at = int(np.searchsorted(fx_t, t0, side="right")) - 1
        end = int(np.searchsorted(fx_t, t1, side="right")) - 1
        here = (lat[at], lon[at]) if at >= 0 else (np.nan, np.nan)
        there = (lat[end], lon[end]) if end >= 0 else (np.nan, np.nan)
        evidence = {"satellite": f"E{int(rows['svid'].iat[0]):02d}", "failure": str(rows["kind"].iat[0]), "failures": len(rows),
                    "detail": str(rows["detail"].iat[0])}  # fmt: skip
        if "gst_s" in rows:
            wn, tow = divmod(int(rows["gst_s"].iat[0]), 604_800)
            evidence["first_gst"] = f"WN {wn} TOW {tow}"
        out.append(_finding("osnma_failure", (max(at, 0), max(end, 0)), t0, t1, *here, *there, **evidence))
    for item in out:
        item.pop("_rows")
    return sorted(out, key=lambda item: (item["start_utc"], item["evidence"]["satellite"], item["evidence"]["failure"]))
