"""RAIM measurements from the NMEA epoch and satellite tables (ALGORITHMS.md §9).

* Geometry: GSV elevation/azimuth of the satellites GSA lists as used; one
  receiver clock per constellation in use. Many receivers send GSV only every
  few seconds: a used satellite without angles in its epoch takes the latest
  angles reported for it at most ``max_angle_age_s`` earlier (satellites move
  about 0.5° a minute); without any it is left out of the RAIM (it still counts
  in the receiver's ``n_used``).
* Test statistic: from GRS residuals exactly (t = Σ r_i²/σ_i², source ``grs``);
  otherwise from the GST RMS where it is a plausible range RMS
  (:mod:`tollcli.gnss.receiver_outputs`), t ≈ rms²·Σ 1/σ_i², source ``gst``; with
  neither, no residual test (``none``).
* The receiver's own integrity outputs (GBS, the GST ellipse) ride along as
  :class:`~tollcli.gnss.receiver_outputs.ReceiverOutputs` for the integrity verdicts.
* σ: the named model per used satellite; under the nominal model an epoch whose fix the receiver says is
  corrected (:data:`CORRECTED_QUALITIES`: GGA quality 2 DGNSS/SBAS, 4 RTK fixed, 5 RTK float, 9 SBAS; u-blox
  ``diffSoln``/``carrSoln``, gpsd DGPS/RTK, RTKLIB fix/float/DGPS map onto them) gets the corrected ionosphere's σ
  (``iono="sbas"``, paper 004's σ_UIRE) — the RAIM's and the ``model`` level's σ alike, a fixed solution the same
  as a float one (at least the corrected σ: no weaker). The ``model`` level keeps that σ where no residual measured
  the environment (:func:`tollcli.integrity.environment.with_environment`): a receiver holding corrections, or
  carrier-phase ambiguities, on its satellites is not the unknown street the urban σ assumes.
* Duplicated satellites in an epoch are counted once.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.measurements import Measurements, pad, slots, sv_labels
from tollcli.gnss.receiver_outputs import RmsCarry, receiver_outputs
from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.gnss.wls import observation_matrix
from tollcli.io.columns import Coded, Columns, column_array, sorted_codes

MAX_ANGLE_AGE_S = 30.0
#: GGA fix qualities of a corrected solution: 2 DGNSS/SBAS, 4 RTK fixed, 5 RTK float, 9 SBAS (some makes)
CORRECTED_QUALITIES = (2, 4, 5, 9)


def corrected_fixes(epochs: pd.DataFrame) -> np.ndarray:
    """Per epoch: the receiver says its fix is corrected (:data:`CORRECTED_QUALITIES`)."""
    if "fix_quality" not in epochs:
        return np.zeros(len(epochs), bool)
    return np.isin(pd.to_numeric(epochs["fix_quality"], errors="coerce").to_numpy(float), CORRECTED_QUALITIES)


class AngleCarry:
    """What one chunk hands the next: the latest GSV angles per satellite, and the GST RMS verdict."""

    def __init__(self) -> None:
        self.rms = RmsCarry()
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


def _constellation_codes(constellation: pd.Series, rows: np.ndarray,
                         coded: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The constellation codes of ``rows`` and the names they index (sorted; names no row has may be among them:
    :func:`_compact` drops them). The reader's Arrow strings are coded whole, without making a Python string of every
    row (``coded``: :func:`_arrow_coded` of the column when already made); a column with a missing name is coded as
    ``pandas.factorize`` codes objects (a missing name last, as NaN)."""
    coded = coded if coded is not None else _arrow_coded(constellation)
    if coded is not None:
        codes, names = coded
        return codes[rows], names
    return pd.factorize(constellation.to_numpy(dtype=object)[rows], sort=True, use_na_sentinel=False)


def _arrow_coded(constellation: pd.Series) -> tuple[np.ndarray, np.ndarray] | None:
    """Every row's code and the names (sorted, as objects) of the reader's Arrow string column without a missing name;
    None for another column (a missing name, or objects). (The reader's :class:`~tollcli.io.columns.Coded` column:
    :func:`~tollcli.io.columns.sorted_codes`, where names no row has may be among them.)"""
    if isinstance(constellation.array, pd.arrays.ArrowStringArray) and not constellation.hasnans:
        codes, names = pd.factorize(constellation.array, sort=True)
        return codes, np.asarray(names, dtype=object)
    return None


def _compact(code: np.ndarray, names) -> tuple[np.ndarray, np.ndarray]:
    """Codes renumbered over the names still present (kept in their order)."""
    present = np.flatnonzero(np.bincount(code, minlength=len(names))) if code.size else np.zeros(0, np.int64)
    remap = np.full(len(names), -1, np.int64)
    remap[present] = np.arange(present.size)
    return remap[code], np.asarray(names, dtype=object)[present]


def _lookup(keys: np.ndarray, values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """``values`` at the place of each ``wanted`` key in ``keys`` (unique), NaN where absent."""
    if not keys.size:
        return np.full(wanted.shape, np.nan)
    if not (keys[1:] > keys[:-1]).all():  # the reader's epoch numbers are in order: no sort needed
        order = np.argsort(keys, kind="stable")
        keys, values = keys[order], values[order]
    if keys.dtype.kind in "iu" and wanted.dtype.kind in "iu" and int(keys[-1]) - int(keys[0]) == keys.size - 1:  # consecutive:
        pos = wanted - keys[0]  # (a chunk's epoch numbers) each key's place is its distance from the first
        inside = (pos >= 0) & (pos < keys.size)
        return np.where(inside, values[np.where(inside, pos, 0)], np.nan)
    pos = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
    return np.where(keys[pos] == wanted, values[pos], np.nan)


def fill_angles(satellites: pd.DataFrame | Columns, epochs: pd.DataFrame, carry: AngleCarry | None = None,
                max_age_s: float = MAX_ANGLE_AGE_S, coded: tuple[np.ndarray, np.ndarray] | None = None) -> pd.DataFrame:  # fmt: skip
    """The satellite table with missing angles taken from the same satellite's latest GSV.

    Returned as given (not copied) when no used satellite lacks its angles; else a DataFrame. ``coded``:
    :func:`_arrow_coded` of its constellation column, when made (the latest angles are then picked by code, not by
    name: the same rows); needed for :class:`~tollcli.io.columns.Columns`.
    """
    t_s = _lookup(epochs["epoch"].to_numpy(), _epoch_seconds(epochs), column_array(satellites, "epoch"))
    elev, azim = column_array(satellites, "elev_deg", float), column_array(satellites, "azim_deg", float)
    seen = np.isfinite(elev) & np.isfinite(azim)
    fresh = seen & np.isfinite(t_s)
    missing = ~seen & column_array(satellites, "used", bool) & np.isfinite(t_s)
    if missing.any():
        sats = satellites.to_pandas() if isinstance(satellites, Columns) else satellites.copy()
        sats["t_s"] = t_s
        sats["constellation"] = sats["constellation"].astype(object)
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
        if carry is not None and len(known):
            carry.last = _latest_table({c: known[c].to_numpy() for c in _KNOWN})
        return sats.drop(columns="t_s")
    if carry is not None:  # nothing to fill: only each satellite's latest angles are kept, from fewer rows
        idx = np.flatnonzero(fresh)
        svid = column_array(satellites, "svid")[idx]
        if coded is not None:  # codes in the names' sorted order: the same groups, in the same order, as the names
            code = coded[0][idx]
            latest = _latest_rows(t_s[idx], code, svid)
            names = coded[1][code[latest]]
        else:
            const = satellites["constellation"].array[idx]  # as read (an Arrow array: only the latest rows become objects)
            latest = _latest_rows(t_s[idx], const, svid)
            names = np.asarray(const[latest], dtype=object)
        last = carry.last
        known = {"t_s": t_s[idx][latest], "constellation": names, "svid": svid[latest],
                 "elev_deg": elev[idx][latest], "azim_deg": azim[idx][latest]}  # fmt: skip
        known = {c: np.concatenate([last[c].to_numpy(), known[c]]).astype(kind) for c, kind in _KNOWN.items()}
        if known["t_s"].size:
            carry.last = _latest_table(known)
    return satellites


def _latest_table(known: dict[str, np.ndarray]) -> pd.DataFrame:
    """The latest angles per satellite of ``known`` (columns of ``_KNOWN``) as the carried table."""
    rows = _latest_rows(known["t_s"], known["constellation"], known["svid"])
    return pd.DataFrame({c: pd.Series(known[c][rows], dtype=kind) for c, kind in _KNOWN.items()})


#: the columns (and types) of the angles kept for later epochs
_KNOWN = {"t_s": float, "constellation": object, "svid": np.int64, "elev_deg": float, "azim_deg": float}


def _latest_rows(t_s: np.ndarray, constellation, svid: np.ndarray) -> np.ndarray:
    """Per (constellation, svid), the row with the latest time (of equal times, the later row), in sorted key order.

    What ``DataFrame.sort_values("t_s", kind="stable").groupby([...]).last()`` picks, for
    rows without missing values; rows without a constellation are no group, as in groupby. ``constellation``: any
    array ``pandas.factorize`` takes (names as objects, or the reader's Arrow strings), or integer codes ≥ 0 in the
    names' sorted order (:func:`_arrow_coded`: taken as they are, the same groups in the same order).
    """
    t_s = np.asarray(t_s, float)
    order = np.arange(t_s.size) if not (np.diff(t_s) < 0).any() else np.argsort(t_s, kind="stable")  # a log's rows: in time
    if isinstance(constellation, np.ndarray) and constellation.dtype.kind in "iu":
        const = constellation
    else:
        const, _ = pd.factorize(constellation, sort=True)  # no constellation: -1
    svid = np.asarray(svid, np.int64)
    ordered = order[const[order] >= 0]
    if not ordered.size:
        return ordered
    low = int(svid[ordered].min())
    width = int(svid[ordered].max()) - low + 1
    key = const[ordered].astype(np.int64) * width + (svid[ordered] - low)  # dense, in (constellation, svid) order
    last = np.full(int(key.max()) + 1, -1, np.int64)
    np.maximum.at(last, key, np.arange(ordered.size))  # each key's last place in time order
    return ordered[last[last >= 0]]


def nmea_measurements(
    epochs: pd.DataFrame,
    satellites: pd.DataFrame | Columns,
    sigma_model: str = "nominal",
    sigma_m: float = 5.0,
    nominal: NominalModel | None = None,
    carry: AngleCarry | None = None,
) -> Measurements:
    """Padded RAIM inputs for every row of ``epochs`` (``carry``: GSV angles from earlier chunks). ``satellites``: the
    satellite table as a DataFrame or as the reader's :class:`~tollcli.io.columns.Columns` (the same measurements;
    no frame is built unless angles must be filled in)."""
    n_epochs = len(epochs)
    held = satellites.held("constellation") if isinstance(satellites, Columns) and "constellation" in satellites else None
    if isinstance(held, Coded):  # the reader's coded names: their codes, in the names' order
        coded = sorted_codes(held)
    else:  # a frame (names as objects in columns: made one)
        satellites = satellites.to_pandas() if isinstance(satellites, Columns) else satellites
        coded = _arrow_coded(satellites["constellation"])  # once, for the angles carried and the clocks
    filled = fill_angles(satellites, epochs, carry, coded=coded)
    if filled is not satellites:  # (angles filled: a copy, its names as objects)
        satellites, coded = filled, None
    elev_all, azim_all = column_array(satellites, "elev_deg", float), column_array(satellites, "azim_deg", float)
    take = np.flatnonzero(column_array(satellites, "used", bool) & np.isfinite(elev_all) & np.isfinite(azim_all))
    # constellation names coded once, in name order (a receiver clock per constellation, in name order)
    code_all, names = _constellation_codes(None if coded is not None else satellites["constellation"], take, coded)
    sat_epoch = column_array(satellites, "epoch")
    svid_all = column_array(satellites, "svid")
    first = _first_of_each(sat_epoch[take].astype(np.int64), code_all, svid_all[take].astype(np.int64))
    take, code_all = take[first], code_all[first]  # = drop_duplicates on the three
    epoch_ids = epochs["epoch"].to_numpy()
    used_epoch = sat_epoch[take]
    row = np.searchsorted(epoch_ids, used_epoch)
    keep = (row < n_epochs) & (epoch_ids[np.minimum(row, max(n_epochs - 1, 0))] == used_epoch) if n_epochs else np.zeros(take.size, bool)
    order = np.flatnonzero(keep)[np.argsort(row[keep], kind="stable")]
    take, row, clock = take[order], row[order], code_all[order]
    used = {c: column_array(satellites, c, float)[take] for c in ("cn0_dbhz", "residual_m")}
    used.update(elev_deg=elev_all[take], azim_deg=azim_all[take], svid=svid_all[take])
    slot, n_slots = slots(row, n_epochs)
    shape = (n_epochs, n_slots)

    clock, names = _compact(clock, names)  # the constellations of this chunk's used satellites
    if len(names) and not pd.isna(names).any():  # coded for the σ model and the labels (no string compared)
        const = pd.Categorical.from_codes(clock, categories=pd.Index(names, dtype=object))
    else:
        const = names[clock] if len(names) else np.empty(0, object)
    elev_used, azim_used, cn0_used = used["elev_deg"], used["azim_deg"], used["cn0_dbhz"]
    elev = pad(elev_used, row, slot, shape, np.nan)
    azim = pad(azim_used, row, slot, shape, np.nan)
    clock_pad = pad(clock.astype(np.int64), row, slot, shape, -1)
    mask = pad(np.ones(take.size, dtype=bool), row, slot, shape, False)
    H = observation_matrix(elev, azim, clock_pad, len(names))

    lat = epochs["lat_deg"].to_numpy(float)[row]
    lon = epochs["lon_deg"].to_numpy(float)[row]
    sig = sigma_for(
        sigma_model, elev_deg=elev_used, cn0_dbhz=cn0_used, constellation=const, lat_deg=np.nan_to_num(lat), lon_deg=np.nan_to_num(lon), sigma_const_m=sigma_m, nominal=nominal,
    )  # fmt: skip
    quality = epochs["fix_quality"].to_numpy()[row] if "fix_quality" in epochs else np.zeros(row.size, np.int64)
    sbas = np.isin(quality, CORRECTED_QUALITIES) & (sigma_model == "nominal")  # a corrected fix (DGNSS/SBAS, RTK)
    if sbas.any() and (nominal or NominalModel()).iono == "single":  # the corrected ionosphere: paper 004's σ_UIRE
        from dataclasses import replace as _with

        corrected = sigma_for(
            sigma_model, elev_deg=elev_used[sbas], cn0_dbhz=cn0_used[sbas],
            constellation=np.asarray(const)[sbas], lat_deg=np.nan_to_num(lat[sbas]), lon_deg=np.nan_to_num(lon[sbas]),
            sigma_const_m=sigma_m, nominal=_with(nominal or NominalModel(), iono="sbas"),
        )  # fmt: skip
        sig = np.array(sig, dtype=float, copy=True)
        sig[sbas] = corrected
    sigma = pad(sig, row, slot, shape, np.nan)
    residual = pad(used["residual_m"], row, slot, shape, np.nan)
    labels = pad(sv_labels(const, used["svid"]), row, slot, shape, "")

    have_grs = mask.any(axis=1) & ~(mask & ~np.isfinite(residual)).any(axis=1)
    receiver = receiver_outputs(epochs, carry.rms if carry is not None else None)
    weight_sum = np.where(mask, 1.0 / np.where(mask, sigma, 1.0) ** 2, 0.0).sum(axis=1)
    gst_stat = np.where(~have_grs & np.isfinite(receiver.gst_rms_m), receiver.gst_rms_m**2 * weight_sum, np.nan)
    source = np.where(have_grs, "grs", np.where(np.isfinite(gst_stat), "gst", "none")).astype(object)
    reported = np.isin(epoch_ids, sat_epoch) if n_epochs else np.zeros(0, bool)
    return Measurements(H, sigma, mask, labels, residual_m=np.where(have_grs[:, None], residual, np.nan),
                        test_stat_override=gst_stat, test_stat_source=source, satellites_reported=reported,
                        receiver=receiver, cn0_dbhz=pad(cn0_used, row, slot, shape, np.nan),
                        corrected_fix=corrected_fixes(epochs))  # fmt: skip
