"""What OSNMA verified → per epoch and Galileo satellite whether its navigation data were authenticated then.

A satellite's data are authenticated at an epoch when the data set its pages carried last before that epoch
(its words 1–5, told apart by their digest ``data_key``: a word changed under the same IOD is another data
set) had been authenticated by then: ``nav_auth_adkd0`` by ADKD 0 tags (fast MAC, the key one
subframe later), ``nav_auth_adkd12`` by ADKD 12 tags (slow MAC, ten subframes later); ``nav_authenticated``
is either; ``nav_auth_gst_s`` is when that data set was first authenticated (GST seconds), ``iod`` its issue of data. An authentication is
known at the receiver 2 s after the page that completed it began (the page's end). After a change of IOD
a satellite is unauthenticated until tags over the new data verified (about one to six minutes).

Epoch times are UTC; GST = GPS time = UTC + leap seconds, counted here from the GST origin (1999-08-22).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.osnma.receiver import OsnmaResult
from tollcli.gnss.osnma.tesla import WEEK_S
from tollcli.readers.gps_time import LEAP_SECONDS

#: GST week 0 began at GPS week 1024
GST_ORIGIN_GPS_S = 1024 * WEEK_S
#: a verification is known this long after its page's time label (s)
KNOWN_AFTER_S = 2


def utc_to_gst_s(time_utc) -> np.ndarray:
    """UTC timestamps → GST seconds since the GST origin (leap seconds added)."""
    t = pd.to_datetime(pd.Series(time_utc), utc=True).dt.tz_localize(None).to_numpy("datetime64[ns]")
    leap = np.zeros(len(t), dtype=np.int64)
    for date, seconds in LEAP_SECONDS:
        leap = np.where(t >= np.datetime64(date, "ns"), seconds, leap)
    gps_s = (t - np.datetime64("1980-01-06T00:00:00", "ns")).astype(np.int64) / 1e9 + leap
    return gps_s - GST_ORIGIN_GPS_S


def _first_auth(result: OsnmaResult, adkd: int) -> pd.DataFrame:
    d = result.data[result.data["adkd"] == adkd]
    out = d.groupby(["prn_d", "data_key"], as_index=False)["at_s"].min().rename(columns={"prn_d": "svid"})
    out["known_s"] = out.pop("at_s") + KNOWN_AFTER_S
    return out


def satellite_status(result: OsnmaResult, satellites: pd.DataFrame) -> pd.DataFrame:
    """``satellites`` (one row per epoch and satellite: ``time_utc``, ``constellation``, ``svid``) with ``iod``,
    ``nav_auth_adkd0``, ``nav_auth_adkd12``, ``nav_authenticated`` and ``nav_auth_gst_s`` (non-Galileo rows: False/NaN)."""
    out = satellites.copy()
    n = len(out)
    out["gst_s"] = utc_to_gst_s(out["time_utc"]) if n else np.zeros(0)
    gal = (out["constellation"].to_numpy(object) == "Galileo") if n else np.zeros(0, bool)
    rows = pd.DataFrame({"_i": np.flatnonzero(gal), "svid": out["svid"].to_numpy(np.int64)[gal], "t": out["gst_s"].to_numpy(float)[gal]})
    iods = result.iods.assign(t=result.iods["gst_s"].astype(float) + KNOWN_AFTER_S).sort_values("t", kind="stable")
    iods = iods.astype({"svid": np.int64})  # (a log that authenticated nothing has empty, untyped tables)
    rows = pd.merge_asof(rows.sort_values("t"), iods[["svid", "t", "iod", "data_key"]], on="t", by="svid", direction="backward")
    known = {}
    for adkd in (0, 12):
        first = _first_auth(result, adkd)
        first = first.astype({"svid": np.int64, "data_key": rows["data_key"].dtype}) if first.empty else first
        rows = rows.merge(first.rename(columns={"known_s": f"k{adkd}"}), on=["svid", "data_key"], how="left")
        known[adkd] = rows[f"k{adkd}"].to_numpy(float) <= rows["t"].to_numpy(float)
    for adkd in (0, 12):
        col = np.zeros(n, bool)
        col[rows["_i"].to_numpy()] = known[adkd]
        out[f"nav_auth_adkd{adkd}"] = col
    out["nav_authenticated"] = out["nav_auth_adkd0"] | out["nav_auth_adkd12"]
    first_known = np.fmin(np.where(known[0], rows["k0"], np.nan), np.where(known[12], rows["k12"], np.nan)) - KNOWN_AFTER_S
    when = np.full(n, np.nan)
    when[rows["_i"].to_numpy()] = first_known
    out["nav_auth_gst_s"] = when
    iod = np.full(n, None, dtype=object)
    iod[rows["_i"].to_numpy()] = rows["iod"].to_numpy(object)
    out["iod"] = iod
    return out


def epoch_counts(status: pd.DataFrame) -> pd.DataFrame:
    """Per epoch: ``n_galileo_used`` and ``n_used_authenticated`` (used Galileo satellites whose data were authenticated)."""
    used = status["used"].to_numpy(bool) & (status["constellation"].to_numpy(object) == "Galileo")
    frame = pd.DataFrame({"epoch": status["epoch"], "time_utc": status["time_utc"], "gst_s": status["gst_s"],
                          "n_galileo_used": used, "n_used_authenticated": used & status["nav_authenticated"].to_numpy(bool),
                          "n_galileo_tracked": status["constellation"].to_numpy(object) == "Galileo",
                          "n_tracked_authenticated": status["nav_authenticated"].to_numpy(bool)})  # fmt: skip
    return frame.groupby(["epoch", "time_utc", "gst_s"], as_index=False, sort=True).sum()
