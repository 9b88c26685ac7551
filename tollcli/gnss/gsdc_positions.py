"""WLS positions and RAIM measurements from the Google Smartphone Decimeter Challenge "derived" CSV.

Per satellite-signal row the file gives the satellite's ECEF position at signal
transmission time (in the ECEF frame of that time), its clock bias and the
modelled delays. Corrected pseudorange (the data set's own definition):

    pr = rawPrM + satClkBiasM − isrbM − ionoDelayM − tropoDelayM

With ``isrbM`` removed one receiver clock serves every constellation and signal.
The position is the iterated, Sagnac-corrected WLS of
:mod:`tollcli.gnss.pseudorange_wls`, batched over epochs. Every signal (L1 and L5 of one
satellite) is its own measurement; duplicated rows count once. The file is read
by :mod:`tollcli.readers.gsdc`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements, pad, slots, sv_labels
from tollcli.gnss.pseudorange_wls import final_geometry, solvable, solve_positions
from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.readers.gps_time import gps_millis_to_utc
from tollcli.readers.gsdc import ANDROID_CONSTELLATION


def gsdc_epochs(
    derived: pd.DataFrame,
    sigma_model: str = "input",
    sigma_m: float = 5.0,
    nominal: NominalModel | None = None,
) -> tuple[pd.DataFrame, Measurements]:
    """WLS position per epoch (an epoch table) and the RAIM measurements at that position."""
    d = derived.drop_duplicates(["millisSinceGpsEpoch", "constellationType", "svid", "signalType"])
    epoch_millis = np.unique(d["millisSinceGpsEpoch"].to_numpy(np.int64))  # every epoch keeps its row
    pr = (d["rawPrM"] + d["satClkBiasM"] - d["isrbM"] - d["ionoDelayM"] - d["tropoDelayM"]).to_numpy(float)
    good = np.isfinite(pr) & np.isfinite(d[["xSatPosM", "ySatPosM", "zSatPosM"]].to_numpy(float)).all(axis=1)
    d, pr = d[good], pr[good]
    row = np.searchsorted(epoch_millis, d["millisSinceGpsEpoch"].to_numpy(np.int64))
    order = np.argsort(row, kind="stable")
    d, pr, row = d.iloc[order], pr[order], row[order]
    n_epochs = epoch_millis.size
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)
    mask = pad(np.ones(len(d), dtype=bool), row, slot, shape, False)
    sat = np.stack([pad(d[c].to_numpy(float), row, slot, shape, 0.0) for c in ("xSatPosM", "ySatPosM", "zSatPosM")], -1)
    prp = pad(pr, row, slot, shape, 0.0)
    unc = pad(d["rawPrUncM"].to_numpy(float), row, slot, shape, np.nan)
    # labels and constellation names: computed once per distinct satellite-signal, then indexed
    keys = d[["constellationType", "svid", "signalType"]]
    codes, uniques = pd.factorize(pd.MultiIndex.from_frame(keys))
    u = pd.DataFrame(list(uniques), columns=list(keys.columns))
    u_const = u["constellationType"].astype(int).map(ANDROID_CONSTELLATION).fillna("unknown").to_numpy(object)
    u_label = sv_labels(u_const, u["svid"].to_numpy()) + " " + u["signalType"].astype(str).str.split("_").str[-1].to_numpy(object)
    const_rows = u_const[codes]
    const_pad = pad(const_rows, row, slot, shape, "")
    labels = pad(u_label[codes], row, slot, shape, "")

    sigma_iter = np.where(mask, np.where(np.isfinite(unc) & (unc > 0), unc, sigma_m), np.nan)
    x = solve_positions(sat, prp, mask, sigma_iter)
    g = final_geometry(sat, prp, mask, x)
    lat, lon, height = g["lat_deg"], g["lon_deg"], g["height_m"]
    sigma = np.where(
        mask,
        sigma_for(sigma_model, elev_deg=g["elev_deg"], cn0_dbhz=np.full(shape, np.nan), constellation=const_pad,
                  lat_deg=lat[:, None], lon_deg=lon[:, None], sigma_input_m=unc, sigma_const_m=sigma_m, nominal=nominal),
        np.nan,
    )  # fmt: skip
    H_enu, dy = g["H"], g["dy_m"]
    ok = solvable(mask)  # (one clock: four measurements)
    epochs = pd.DataFrame(
        {
            "epoch": np.arange(n_epochs, dtype=np.int64),
            "time_utc": pd.DatetimeIndex(gps_millis_to_utc(epoch_millis)).tz_localize("UTC"),
            "gps_millis": epoch_millis,
            "lat_deg": np.where(ok, lat, np.nan),
            "lon_deg": np.where(ok, lon, np.nan),
            "height_m": np.where(ok, height, np.nan),
            "clock_bias_m": np.where(ok, x[:, 3], np.nan),
            "n_measurements": mask.sum(axis=1).astype(np.int16),
        }
    )
    source = np.full(n_epochs, "pseudorange", dtype=object)
    meas = Measurements(H_enu, sigma, mask, labels, dy_m=dy, test_stat_source=source, sat_ecef_m=sat, pr_m=g["pr_m"],
                        clock_index=g["clock_index"])
    return epochs, meas
