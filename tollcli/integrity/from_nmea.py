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


def fill_angles(satellites: pd.DataFrame, epochs: pd.DataFrame, carry: AngleCarry | None = None,
                max_age_s: float = MAX_ANGLE_AGE_S) -> pd.DataFrame:  # fmt: skip
    """The satellite table with missing angles taken from the same satellite's latest GSV."""
    sats = satellites.copy()
    t_of_epoch = pd.Series(_epoch_seconds(epochs), index=epochs["epoch"].to_numpy())
    sats["t_s"] = t_of_epoch.reindex(sats["epoch"].to_numpy()).to_numpy()
    sats["constellation"] = sats["constellation"].astype(object)
    seen = np.isfinite(sats["elev_deg"]) & np.isfinite(sats["azim_deg"])
    known = pd.concat([carry.last if carry is not None else None,
                       sats.loc[seen, ["t_s", "constellation", "svid", "elev_deg", "azim_deg"]]], ignore_index=True)  # fmt: skip
    known = known.astype({"t_s": float, "svid": np.int64, "elev_deg": float, "azim_deg": float, "constellation": object})
    known = known.dropna(subset=["t_s"]).sort_values("t_s", kind="stable")
    missing = ~seen & sats["used"].to_numpy(dtype=bool) & np.isfinite(sats["t_s"])
    if missing.any() and len(known):
        left = sats.loc[missing, ["t_s", "constellation", "svid"]].astype({"svid": np.int64}).reset_index()
        filled = pd.merge_asof(left.sort_values("t_s", kind="stable"), known, on="t_s",
                               by=["constellation", "svid"], direction="backward", tolerance=max_age_s)  # fmt: skip
        filled = filled.set_index("index")
        sats.loc[filled.index, "elev_deg"] = filled["elev_deg"]
        sats.loc[filled.index, "azim_deg"] = filled["azim_deg"]
    if carry is not None and len(known):
        carry.last = known.groupby(["constellation", "svid"], as_index=False).last()
    return sats.drop(columns="t_s")


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
    used = used.drop_duplicates(["epoch", "constellation", "svid"])
    epoch_ids = epochs["epoch"].to_numpy()
    row = np.searchsorted(epoch_ids, used["epoch"].to_numpy())
    keep = (row < n_epochs) & (epoch_ids[np.minimum(row, max(n_epochs - 1, 0))] == used["epoch"].to_numpy()) if n_epochs else np.zeros(len(used), bool)
    used, row = used[keep], row[keep]
    order = np.argsort(row, kind="stable")
    used, row = used.iloc[order], row[order]
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)

    const = used["constellation"].to_numpy(dtype=object)
    names = sorted(set(const))
    clock = np.searchsorted(np.asarray(names, dtype=object), const) if names else np.zeros(0, int)
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
