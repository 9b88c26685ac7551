"""u-blox ``RXM-RAWX`` rows → the raw-measurement table of :mod:`tollcli.gnss.raw_positions`, and
``RXM-SFRBX`` navigation data (GPS LNAV subframes, Galileo I/NAV page pairs, BeiDou D1 subframes, GLONASS strings)
→ an ephemeris table.

RAWX gives the pseudorange directly (m, receiver time ``week``·604 800 + ``rcvTow`` in the GPS scale
of the receiver's clock); the Doppler D (Hz) becomes the pseudorange rate −D·λ; the standard
deviations are coded 0.01·2ⁿ m and 0.002·2ⁿ Hz. A pseudorange is used when the receiver flags it
valid (``prValid``) and it lies in the physical range.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss import inav_words, lnav_subframes
from tollcli.gnss.android_raw import PHYSICAL_RANGE_M
from tollcli.gnss.measurements import sv_labels
from tollcli.gnss.orbits import WEEK_S
from tollcli.readers.ubx import GNSS_ID, UbxRead

C_MPS = 299_792_458.0
#: (gnssId, sigId) → (signal, carrier Hz); GLONASS carriers add freqId − 7 channels
SIGNALS = {(0, 0): ("L1", 1575.42e6), (0, 3): ("L2", 1227.60e6), (0, 4): ("L2", 1227.60e6), (0, 6): ("L5", 1176.45e6),
           (0, 7): ("L5", 1176.45e6), (1, 0): ("L1", 1575.42e6), (2, 0): ("E1", 1575.42e6), (2, 1): ("E1", 1575.42e6),
           (2, 3): ("E5a", 1176.45e6), (2, 4): ("E5a", 1176.45e6), (2, 5): ("E5b", 1207.14e6), (2, 6): ("E5b", 1207.14e6),
           (3, 0): ("B1I", 1561.098e6), (3, 1): ("B1I", 1561.098e6), (3, 2): ("B2I", 1207.14e6), (3, 3): ("B2I", 1207.14e6),
           (3, 7): ("B2a", 1176.45e6), (3, 8): ("B2a", 1176.45e6), (3, 4): ("B3I", 1268.52e6), (3, 10): ("B3I", 1268.52e6),
           (3, 5): ("B1C", 1575.42e6), (3, 6): ("B1C", 1575.42e6), (2, 8): ("E6", 1278.75e6), (2, 9): ("E6", 1278.75e6),
           (5, 0): ("L1", 1575.42e6), (5, 1): ("L1", 1575.42e6), (5, 4): ("L2", 1227.60e6),
           (5, 5): ("L2", 1227.60e6), (6, 0): ("G1", 1602.0e6), (6, 2): ("G2", 1246.0e6)}  # fmt: skip
#: BeiDou signals whose navigation message is D1 or D2 (B1I, B2I, B3I: u-blox sigId 0–4, 10)
BEIDOU_D_SIGNALS = (0, 1, 2, 3, 4, 10)


def rawx_measurements(ubx: UbxRead) -> pd.DataFrame:
    """One row per RAWX measurement in the raw-measurement table layout."""
    r = ubx.rawx
    gnss = r["gnssId"].to_numpy(np.int64)
    sig = r["sigId"].to_numpy(np.int64)
    constellation = pd.Series(gnss).map(GNSS_ID).fillna("unknown").to_numpy(object)
    found = [SIGNALS.get((g, s), ("", np.nan)) for g, s in zip(gnss.tolist(), sig.tolist())]
    signal = np.array([f[0] for f in found], dtype=object)
    carrier = np.array([f[1] for f in found], dtype=float)
    glo = gnss == 6
    channel = r["freqId"].to_numpy(float) - 7
    carrier[glo & (sig == 0)] = 1602.0e6 + channel[glo & (sig == 0)] * 0.5625e6
    carrier[glo & (sig == 2)] = 1246.0e6 + channel[glo & (sig == 2)] * 0.4375e6
    t = r["week"].to_numpy(float) * WEEK_S + r["rcvTow"].to_numpy(float)
    pr = r["prMes"].to_numpy(float)
    lam = C_MPS / carrier
    svid = r["svId"].to_numpy(np.int64)
    valid = (r["prValid"].to_numpy(float) == 1) & (pr > PHYSICAL_RANGE_M[0]) & (pr < PHYSICAL_RANGE_M[1])
    valid &= np.isin(constellation, ["GPS", "Galileo", "BeiDou", "QZSS", "GLONASS"])
    why = np.where(valid, "", np.where(r["prValid"].to_numpy(float) == 1, "pseudorange outside the physical range or system not used",
                                       "receiver flags the pseudorange invalid"))  # fmt: skip
    return pd.DataFrame({
        "epoch_key": np.round(t * 1000).astype(np.int64),
        "t_rx_gps_s": t,
        "constellation": constellation,
        "svid": svid,
        "sv": sv_labels(constellation, svid),
        "signal": signal,
        "carrier_hz": carrier,
        "pr_m": pr,
        "pr_sigma_m": 0.01 * 2.0 ** r["prStd"].to_numpy(float),
        "prr_mps": -r["doMes"].to_numpy(float) * lam,
        "prr_sigma_mps": 0.002 * 2.0 ** r["doStd"].to_numpy(float) * lam,
        "cn0_dbhz": r["cno"].to_numpy(float),
        "pr_valid": valid,
        "pr_invalid_why": why,
        "line": r["message"].to_numpy(np.int64),
    })  # fmt: skip


def sfrbx_ephemerides(ubx: UbxRead, gps_week_hint: float | None = None) -> pd.DataFrame:
    """GPS LNAV, Galileo I/NAV, BeiDou D1 and GLONASS ephemerides decoded from the log's RXM-SFRBX (an empty table
    when there are none).

    GPS L1 C/A subframes (``gnssId`` 0, ``sigId`` 0, ten words) carry a 10-bit week resolved near
    ``gps_week_hint`` (default: the RAWX week, else the first NAV-PVT's date, else today); Galileo E1-B/E5b-I page
    pairs (``gnssId`` 2, ``sigId`` 1 or 5, eight words or more) carry their own 12-bit GST week; BeiDou D1
    subframes (``gnssId`` 3, B1I/B2I/B3I) their 13-bit BDT week; GLONASS strings (``gnssId`` 6) a time of day, placed
    on the day of the string's receive time (the latest RAWX or NAV-PVT before it in the log)."""
    from tollcli.gnss import beidou_d1, glonass_strings
    from tollcli.readers.gps_time import leap_seconds_at_gps

    sf = ubx.sfrbx
    rows = _decoded_rows(sf)
    gps = sf[rows["gps"]]
    gps = gps.assign(sv=sv_labels(np.full(len(gps), "GPS", dtype=object), gps["svId"].to_numpy()))
    gal = sf[rows["galileo"]]
    gal = gal.assign(sv=sv_labels(np.full(len(gal), "Galileo", dtype=object), gal["svId"].to_numpy()))
    galileo = inav_words.ephemerides(gal.reset_index(drop=True))
    beidou = beidou_d1.ephemerides(sf[rows["beidou"]].reset_index(drop=True))
    glo = sf[rows["glonass"]].reset_index(drop=True)
    glonass = glonass_strings.ephemerides(glo, receive_times_gps_s(ubx, glo["message"].to_numpy()), leap_seconds_at_gps)
    if gps_week_hint is None:
        weeks = ubx.rawx["week"].to_numpy(float) if len(ubx.rawx) else _measured_heads(ubx)["week"].to_numpy(float)
        if weeks.size:
            gps_week_hint = float(np.median(weeks))
        elif len(galileo):
            gps_week_hint = float(np.median(galileo["toe_s"].to_numpy(float)) // WEEK_S)
        else:
            gps_week_hint = _pvt_week(ubx.pvt)
    lnav = lnav_subframes.ephemerides(gps.reset_index(drop=True), gps_week_hint)
    tables = [t for t in (lnav, galileo, beidou, glonass) if len(t)]
    if len(tables) <= 1:
        return tables[0] if tables else lnav
    return pd.concat(tables, ignore_index=True)


def _decoded_rows(sf: pd.DataFrame) -> dict[str, np.ndarray]:
    """Which subframes of ``sf`` each decoder of :func:`sfrbx_ephemerides` reads: GPS L1 C/A (LNAV, ten words),
    Galileo E1-B and E5b-I (I/NAV, eight words or more), BeiDou B1I/B2I/B3I (D1), GLONASS (four words or more)."""
    gnss, sig, n_words = (sf[c].to_numpy(np.int64) for c in ("gnssId", "sigId", "n_words"))
    return {"gps": (gnss == 0) & (sig == 0) & (n_words == 10), "galileo": (gnss == 2) & np.isin(sig, (1, 5)) & (n_words >= 8),
            "beidou": (gnss == 3) & np.isin(sig, BEIDOU_D_SIGNALS), "glonass": (gnss == 6) & (n_words >= 4)}  # fmt: skip


def sfrbx_kept(sf: pd.DataFrame) -> np.ndarray:
    """(n,) the subframes of ``sf`` (the reader's ``sfrbx`` layout, in log order) that can still change the
    ephemerides :func:`sfrbx_ephemerides` makes, whatever subframes follow: each decoder's own (``kept`` of
    :mod:`~tollcli.gnss.lnav_subframes`, :mod:`~tollcli.gnss.inav_words`, :mod:`~tollcli.gnss.beidou_d1`,
    :mod:`~tollcli.gnss.glonass_strings`); none of another system, signal or message (SBAS, almanac pages …). A long
    u-blox log's first pass sifts its subframes through this (``read_ubx(subframes_kept=…)``): the ephemerides are
    the same (``tests/test_ubx_sifting.py``) and the subframes kept are those of the orbits, not of the log."""
    from tollcli.gnss import beidou_d1, glonass_strings

    keep = np.zeros(len(sf), bool)
    for name, rows in _decoded_rows(sf).items():
        at = np.flatnonzero(rows)
        if at.size:
            decoder = {"gps": lnav_subframes, "galileo": inav_words, "beidou": beidou_d1, "glonass": glonass_strings}[name]
            keep[at[decoder.kept(sf.iloc[at].reset_index(drop=True))]] = True
    return keep


def _measured_heads(ubx: UbxRead) -> pd.DataFrame:
    """The RXM-RAWX messages with a measurement (week, rcvTow, message): the log's read without its measurements."""
    heads = ubx.rawx_heads
    if heads is None:
        return pd.DataFrame({"week": np.zeros(0), "rcvTow": np.zeros(0), "message": np.zeros(0, np.int64)})
    return heads[heads["numMeas"].to_numpy() > 0]


def receive_times_gps_s(ubx: UbxRead, message: np.ndarray) -> np.ndarray:
    """The receive time (GPS seconds) of messages at positions ``message`` in the log: that of the latest RAWX
    (its week and receive time of week), else NAV-PVT (its UTC date and time) at or before it, else the first one
    after it; NaN when the log has neither."""
    first = ubx.rawx.drop_duplicates("message") if len(ubx.rawx) else _measured_heads(ubx)
    at, when, _ = _timed_messages(first, ubx.pvt)
    message = np.asarray(message, np.int64)
    if at.size == 0:
        return np.full(message.size, np.nan)
    i = np.searchsorted(at, message, side="right") - 1
    return when[np.clip(i, 0, at.size - 1)]


def _timed_messages(heads: pd.DataFrame, pvt: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The messages that tell a time, in log order: their positions, their GPS times (s) and where each comes from
    (0 … len(heads) - 1: a row of ``heads``, a RAWX with its week and receive time; then len(heads) + k: row k of
    ``pvt``, a NAV-PVT with a date and time that is one)."""
    from tollcli.readers.gps_time import gps_seconds, leap_seconds_at_gps

    at, when = [np.zeros(0, np.int64)], [np.zeros(0)]
    if len(heads):
        at.append(heads["message"].to_numpy(np.int64))
        when.append(heads["week"].to_numpy(float) * WEEK_S + heads["rcvTow"].to_numpy(float))
    if len(pvt):
        p = pvt
        utc = pd.to_datetime(dict(year=p["year"], month=p["month"], day=p["day"], hour=p["hour"], minute=p["minute"],
                                  second=p["second"]), errors="coerce").to_numpy("datetime64[ns]")  # fmt: skip
        seconds = gps_seconds(utc)
        seconds = np.where(np.isnat(utc), np.nan, seconds)
        at.append(p["message"].to_numpy(np.int64))
        when.append(seconds + leap_seconds_at_gps(seconds))
    at, when = np.concatenate(at), np.concatenate(when)
    source = np.flatnonzero(np.isfinite(when))
    source = source[np.argsort(at[source], kind="stable")]
    return at[source], when[source], source


def times_kept(heads: pd.DataFrame, pvt: pd.DataFrame, sf: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(heads, pvt) masks: the RXM-RAWX heads and NAV-PVT rows of a first pass (the reader's ``rawx_heads`` and
    ``pvt`` layouts, in log order, NAV-PVT rows without a plausible date among them) that what reads them can still
    read, whatever messages follow, given the subframes ``sf`` held:

    - the first RAWX with a measurement (:func:`~tollcli.gnss.pseudorange_inputs.ubx_orbits`: the log has some);
    - the first and the last RAWX with a measurement of each GPS week: the week hint of
      :func:`sfrbx_ephemerides` is their median (it undoes a 10-bit week, so any hint within 512 weeks of the true
      one gives the same orbits; the log's own weeks are);
    - the first NAV-PVT with a plausible date (the hint where no RAWX has a measurement);
    - of the messages that tell a time (:func:`receive_times_gps_s`), the first, the last, and for each GLONASS
      string held the latest at or before it: every time a GLONASS string held now or read later is given.

    A long u-blox log's first pass sifts its heads and NAV-PVT rows through this (``read_ubx(times_kept=…)``): the
    ephemerides are the same (``tests/test_ubx_sifting.py``) and the rows kept are bounded."""
    from tollcli.times import plausible_date

    keep_heads, keep_pvt = np.zeros(len(heads), bool), np.zeros(len(pvt), bool)
    dated = np.flatnonzero(plausible_date(*(pvt[c].to_numpy(np.int64) for c in ("year", "month", "day", "hour", "minute", "second"))))
    if dated.size:
        keep_pvt[dated[0]] = True
    measured = np.flatnonzero(heads["numMeas"].to_numpy(np.int64) > 0) if len(heads) else np.zeros(0, np.int64)
    if measured.size:
        week = heads["week"].to_numpy(np.int64)[measured]
        change = np.flatnonzero(np.diff(week) != 0)
        keep_heads[measured[np.concatenate(([0], change, change + 1, [measured.size - 1]))]] = True
    at, _, source = _timed_messages(heads.iloc[measured], pvt.iloc[dated])
    if at.size:
        glonass = sf["message"].to_numpy(np.int64)[_decoded_rows(sf)["glonass"]] if len(sf) else np.zeros(0, np.int64)
        i = np.clip(np.searchsorted(at, glonass, side="right") - 1, 0, at.size - 1)
        chosen = source[np.unique(np.concatenate(([0, at.size - 1], i)))]
        from_heads = chosen < measured.size
        keep_heads[measured[chosen[from_heads]]] = True
        keep_pvt[dated[chosen[~from_heads] - measured.size]] = True
    return keep_heads, keep_pvt


def _pvt_week(pvt: pd.DataFrame) -> float:
    """The GPS week of the receiver's first dated NAV-PVT (the 10-bit week needs one), else today's."""
    if len(pvt):
        first = pvt.iloc[0]
        when = pd.Timestamp(year=int(first["year"]), month=int(first["month"]), day=int(first["day"]))
    else:
        when = pd.Timestamp.now()
    return float((when - pd.Timestamp("1980-01-06")).days // 7)


#: a NAV-PVT further than this from an epoch (s) is not the receiver's solution of that epoch
PVT_TOLERANCE_S = 0.05


#: the receiver's solution columns :func:`with_receiver_solution` adds: NAV-PVT's name → the epoch table's
RECEIVER_COLUMNS = {"lat_deg": "receiver_lat_deg", "lon_deg": "receiver_lon_deg", "height_m": "receiver_height_m",
                    "speed_mps": "receiver_speed_mps", "h_acc_m": "receiver_h_acc_m"}  # fmt: skip


def receiver_solutions(pvt: pd.DataFrame) -> pd.DataFrame:
    """The receiver's fixed NAV-PVT solutions (fix type 2–5) as :func:`with_receiver_solution` matches them: their
    time ``_t`` (UTC, sorted), its GPS time in ms (``epoch_key``, the measurements' time scale: a log read in segments
    carries each segment's solutions beside its rows) and :data:`RECEIVER_COLUMNS` (56 bytes a solution, where a
    NAV-PVT row is 128)."""
    from tollcli.readers.gps_time import gps_seconds, leap_seconds_at_gps

    fixed = pvt[pvt["fix_type"].between(2, 5)] if len(pvt) else pvt
    if fixed.empty:
        return pd.DataFrame({"_t": pd.Series(dtype="datetime64[ns, UTC]"), "epoch_key": pd.Series(dtype=np.int64),
                             **{c: pd.Series(dtype=float) for c in RECEIVER_COLUMNS.values()}})  # fmt: skip
    when = pd.to_datetime(dict(year=fixed["year"], month=fixed["month"], day=fixed["day"], hour=fixed["hour"],
                               minute=fixed["minute"], second=fixed["second"]), utc=True)  # fmt: skip
    when = when + pd.to_timedelta(fixed["nano"].to_numpy(np.int64), unit="ns")
    table = fixed[list(RECEIVER_COLUMNS)].rename(columns=RECEIVER_COLUMNS).assign(_t=when.to_numpy())
    table = table.sort_values("_t").reset_index(drop=True)
    seconds = gps_seconds(table["_t"].dt.tz_convert(None).to_numpy("datetime64[ns]"))
    return table.assign(epoch_key=np.round((seconds + leap_seconds_at_gps(seconds)) * 1000).astype(np.int64))


def with_receiver_solution(epochs: pd.DataFrame, pvt: pd.DataFrame) -> pd.DataFrame:
    """``epochs`` with the receiver's own NAV-PVT solution of the same instant, for comparison:
    ``receiver_lat_deg``, ``receiver_lon_deg``, ``receiver_height_m``, ``receiver_speed_mps``, ``receiver_h_acc_m``
    (NaN where the log has no NAV-PVT within ``PVT_TOLERANCE_S``). ``pvt``: the NAV-PVT table, or its
    :func:`receiver_solutions` made before (None: none)."""
    table = receiver_solutions(pd.DataFrame()) if pvt is None else pvt if "_t" in pvt else receiver_solutions(pvt)
    out = epochs.copy()
    if table.empty or out.empty:
        for name in RECEIVER_COLUMNS.values():
            out[name] = np.nan
        return out
    left = pd.DataFrame({"_t": out["time_utc"].to_numpy(), "_i": np.arange(len(out))}).sort_values("_t")
    table = table.assign(_t=table["_t"].astype(left["_t"].dtype))  # (a copy: a log's table serves every segment)
    merged = pd.merge_asof(left, table, on="_t", direction="nearest",
                           tolerance=pd.Timedelta(seconds=PVT_TOLERANCE_S)).sort_values("_i")  # fmt: skip
    for name in RECEIVER_COLUMNS.values():
        out[name] = merged[name].to_numpy(float)
    return out
