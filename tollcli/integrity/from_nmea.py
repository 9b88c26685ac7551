"""RAIM measurements from the NMEA epoch and satellite tables (ALGORITHMS.md §9).

* Geometry: GSV elevation/azimuth of the satellites GSA lists as used; one
  receiver clock per constellation in use. Many receivers send GSV only every
  few seconds: a used satellite without angles in its epoch takes the latest
  angles reported for it at most ``max_angle_age_s`` earlier (satellites move
  about 0.5° a minute); without any it is left out of the RAIM (it still counts
  in the receiver's ``n_used``).
* Test statistic: from GRS residuals exactly (t = Σ r_i²/σ_i²); otherwise from
  GST as an approximation, t ≈ rms²·Σ 1/σ_i², flagged ``gst_approx``; with
  neither the epoch is ``unmonitored``.
* Duplicated satellites in an epoch are counted once.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.integrity.measurements import Measurements, pad, slots, sv_labels
from tollcli.integrity.sigma_models import NominalModel, sigma_for
from tollcli.integrity.wls import observation_matrix


MAX_ANGLE_AGE_S = 30.0


class AngleCarry:
    """The latest GSV angles per satellite, carried from one chunk to the next."""

    def __init__(self) -> None:
        self.last = pd.DataFrame({"t_s": [], "constellation": [], "svid": [], "elev_deg": [], "azim_deg": []})


def _epoch_seconds(epochs: pd.DataFrame) -> np.ndarray:
    """Seconds on one time axis: UTC when dated, else time of day."""
    utc = epochs["time_utc"]
    secs = utc.dt.tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64) / 1000.0
    return np.where(utc.notna().to_numpy(), secs, epochs["tod_s"].to_numpy(float))


def _first_of_each(epoch: np.ndarray, constellation: np.ndarray, svid: np.ndarray) -> np.ndarray:
    """Rows (in order) that are the first of their (epoch, constellation, svid)."""
    if not epoch.size:
        return np.zeros(0, np.int64)
    const, _ = pd.factorize(constellation, use_na_sentinel=False)
    key = (epoch - epoch.min()) * (1 << 24) + const.astype(np.int64) * (1 << 16) + (svid & 0xFFFF)
    if epoch.max() - epoch.min() >= 1 << 38 or const.max() >= 256 or svid.min() < 0 or svid.max() > 0xFFFF:
        key = np.unique(np.stack([epoch, const, svid], axis=1), axis=0, return_inverse=True)[1].ravel()
    _, first = np.unique(key, return_index=True)
    return np.sort(first)


def _lookup(keys: np.ndarray, values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """``values`` at the place of each ``wanted`` key in ``keys`` (unique), NaN where absent."""
    order = np.argsort(keys, kind="stable")
    pos = np.minimum(np.searchsorted(keys[order], wanted), max(keys.size - 1, 0))
    if not keys.size:
        return np.full(wanted.shape, np.nan)
    hit = keys[order][pos] == wanted
    return np.where(hit, values[order][pos], np.nan)


def fill_angles(satellites: pd.DataFrame, epochs: pd.DataFrame, carry: AngleCarry | None = None,
                max_age_s: float = MAX_ANGLE_AGE_S) -> pd.DataFrame:  # fmt: skip
    """The satellite table with missing angles taken from the same satellite's latest GSV."""
    sats = satellites.copy()
    sats["t_s"] = _lookup(epochs["epoch"].to_numpy(), _epoch_seconds(epochs), sats["epoch"].to_numpy())
    sats["constellation"] = sats["constellation"].astype(object)
    seen = np.isfinite(sats["elev_deg"]) & np.isfinite(sats["azim_deg"])
    fresh = (seen & np.isfinite(sats["t_s"])).to_numpy()
    missing = ~seen & sats["used"].to_numpy(dtype=bool) & np.isfinite(sats["t_s"])
    if missing.any():
        known = pd.concat([carry.last if carry is not None else None, sats.loc[fresh, list(_KNOWN)]], ignore_index=True)
        known = known.astype(_KNOWN)
        if len(known):
            left = sats.loc[missing, ["t_s", "constellation", "svid"]].astype({"svid": np.int64}).reset_index()
            order = np.argsort(known["t_s"].to_numpy(), kind="stable")
            filled = pd.merge_asof(left.sort_values("t_s", kind="stable"), known.iloc[order], on="t_s",
                                   by=["constellation", "svid"], direction="backward", tolerance=max_age_s)  # fmt: skip
            filled = filled.set_index("index")
            sats.loc[filled.index, "elev_deg"] = filled["elev_deg"]
            sats.loc[filled.index, "azim_deg"] = filled["azim_deg"]
    elif carry is not None:  # nothing to fill: only each satellite's latest angles are kept, from fewer rows
        idx = np.flatnonzero(fresh)
        latest = idx[_latest_rows(sats["t_s"].to_numpy()[idx], sats["constellation"].to_numpy()[idx], sats["svid"].to_numpy()[idx])]
        part = pd.DataFrame({c: sats[c].to_numpy()[latest] for c in _KNOWN})
        known = pd.concat([carry.last, part], ignore_index=True).astype(_KNOWN)
    if carry is not None and len(known):
        t = known["t_s"].to_numpy()
        carry.last = known.iloc[_latest_rows(t, known["constellation"].to_numpy(), known["svid"].to_numpy())].reset_index(drop=True)
    return sats.drop(columns="t_s")


#: the columns (and types) of the angles kept for later epochs
_KNOWN = {"t_s": float, "constellation": object, "svid": np.int64, "elev_deg": float, "azim_deg": float}


def _latest_rows(t_s: np.ndarray, constellation: np.ndarray, svid: np.ndarray) -> np.ndarray:
    """Per (constellation, svid), the row with the latest time (of equal times, the later row), in sorted key order.

    What ``DataFrame.sort_values("t_s", kind="stable").groupby([...]).last()`` picks, for
    rows without missing values; rows without a constellation are no group, as in groupby.
    """
    order = np.argsort(t_s, kind="stable")
    const, _ = pd.factorize(np.asarray(constellation, dtype=object), sort=True)  # no constellation: -1
    key = const.astype(np.int64) * (1 << 32) + np.asarray(svid, np.int64)
    ordered = order[const[order] >= 0]
    _, last_rev = np.unique(key[ordered][::-1], return_index=True)  # sorted keys; the first seen backwards = the latest
    return ordered[::-1][last_rev]


def nmea_measurements(
    epochs: pd.DataFrame,
    satellites: pd.DataFrame,
    sigma_model: str = "nominal",
    sigma_m: float = 5.0,
    nominal: NominalModel | None = None,
    carry: AngleCarry | None = None,
) -> Measurements:
    """Padded RAIM inputs for every row of ``epochs`` (``carry``: GSV angles from earlier chunks)."""
    n_epochs = len(epochs)
    satellites = fill_angles(satellites, epochs, carry)
    used = satellites[satellites["used"].to_numpy(dtype=bool)]
    used = used[np.isfinite(used["elev_deg"]) & np.isfinite(used["azim_deg"])]
    used = used.iloc[_first_of_each(used["epoch"].to_numpy(np.int64), used["constellation"].to_numpy(dtype=object),
                                    used["svid"].to_numpy(np.int64))]  # = drop_duplicates on the three  # fmt: skip
    epoch_ids = epochs["epoch"].to_numpy()
    row = np.searchsorted(epoch_ids, used["epoch"].to_numpy())
    keep = (row < n_epochs) & (epoch_ids[np.minimum(row, max(n_epochs - 1, 0))] == used["epoch"].to_numpy()) if n_epochs else np.zeros(len(used), bool)
    used, row = used[keep], row[keep]
    order = np.argsort(row, kind="stable")
    used, row = used.iloc[order], row[order]
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)

    const = used["constellation"].to_numpy(dtype=object)
    clock, names = pd.factorize(const, sort=True, use_na_sentinel=False)  # a receiver clock per constellation, in name order
    elev = pad(used["elev_deg"].to_numpy(float), row, slot, shape, np.nan)
    azim = pad(used["azim_deg"].to_numpy(float), row, slot, shape, np.nan)
    clock_pad = pad(clock.astype(np.int64), row, slot, shape, -1)
    mask = pad(np.ones(len(used), dtype=bool), row, slot, shape, False)
    H = observation_matrix(elev, azim, clock_pad, len(names))

    lat = epochs["lat_deg"].to_numpy(float)[row]
    lon = epochs["lon_deg"].to_numpy(float)[row]
    sig = sigma_for(
        sigma_model, elev_deg=used["elev_deg"].to_numpy(float), cn0_dbhz=used["cn0_dbhz"].to_numpy(float),
        constellation=const, lat_deg=np.nan_to_num(lat), lon_deg=np.nan_to_num(lon), sigma_const_m=sigma_m, nominal=nominal,
    )  # fmt: skip
    sigma = pad(sig, row, slot, shape, np.nan)
    residual = pad(used["residual_m"].to_numpy(float), row, slot, shape, np.nan)
    labels = pad(sv_labels(const, used["svid"].to_numpy()), row, slot, shape, "")

    have_grs = mask.any(axis=1) & ~(mask & ~np.isfinite(residual)).any(axis=1)
    rms = epochs["rms_residual_m"].to_numpy(float) if "rms_residual_m" in epochs else np.full(n_epochs, np.nan)
    weight_sum = np.where(mask, 1.0 / np.where(mask, sigma, 1.0) ** 2, 0.0).sum(axis=1)
    gst_stat = np.where(~have_grs & np.isfinite(rms), rms**2 * weight_sum, np.nan)
    source = np.where(have_grs, "grs", np.where(np.isfinite(gst_stat), "gst_approx", "none")).astype(object)
    return Measurements(H, sigma, mask, labels, residual_m=np.where(have_grs[:, None], residual, np.nan),
                        test_stat_override=gst_stat, test_stat_source=source)  # fmt: skip
