"""Assemble epochs from sentences decoded in bulk, with the rules of :mod:`tollcli.readers.nmea.assembler`.

The bulk path assembles the common epoch: at most one GNS, any number of GGA, RMC, VTG, GST,
GBS, GLL, ZDA (a receiver that writes them once per constellation), GSA and GSV (a satellite
reported on several signals keeps its report as the reference assembler chooses it). Epochs outside that
(:func:`unsupported_epochs`) are assembled per line by the reference assembler.
Every function here works on all epochs of a block at once.
"""

from __future__ import annotations

import numpy as np

from tollcli.readers.nmea import kernels
from tollcli.readers.nmea.assembler import FLOAT_COLUMNS
from tollcli.readers.nmea.bulk_picks import (
    first_finite,
    first_given,
    group_seq,
    last_finite,
    pick,
    scatter,
)
from tollcli.readers.nmea.bulk_sentences import GBS_COLUMNS

SENTENCE_TYPES = ("GGA", "RMC", "VTG", "GSA", "GSV", "GST", "GLL", "ZDA", "GRS", "GBS", "GNS")
SAT_FIELDS = ("sat_row", "sat_k", "sat_const", "sat_svid", "sat_prn", "sat_signal", "sat_elev", "sat_azim", "sat_cn0")
_A, _V = ord("A"), ord("V")
_NOT_FIX = np.array([ord(c) for c in "ENMS"])
_GGA_VALID = (1, 2, 3, 4, 5)
_ONE_CHAR = np.array([""] + [chr(i) for i in range(1, 256)], dtype=object)


def subset(decoded: dict, keep: np.ndarray) -> dict:
    """The decoded rows where ``keep`` holds (satellite rows follow their sentence)."""
    n_keep = int(np.count_nonzero(keep))
    if n_keep == keep.size:
        return dict(decoded)
    if keep[:n_keep].all():  # the first rows (the usual case: the epoch carried to the next block is the last): views
        out = {k: v[:n_keep] for k, v in decoded.items() if not k.startswith("sat_")}
        if "sat_row" in decoded:  # satellite rows follow their sentence's rows in order
            m = int(np.searchsorted(decoded["sat_row"], n_keep))
            out.update({k: decoded[k][:m] for k in SAT_FIELDS if k in decoded})
        return out
    out = {k: v[keep] for k, v in decoded.items() if not k.startswith("sat_")}
    if "sat_row" in decoded:
        new_index = np.cumsum(keep) - 1
        sat_keep = keep[decoded["sat_row"]]
        for k in SAT_FIELDS:
            if k in decoded:
                out[k] = decoded[k][sat_keep]
        out["sat_row"] = new_index[out["sat_row"]]
    return out


def unsupported_epochs(n_epochs: int, s: dict[str, dict]) -> np.ndarray:
    """Epochs the bulk rules do not cover: a repeated GNS, or a GRS with a satellite used twice."""
    bad = np.bincount(s["GNS"]["e"], minlength=n_epochs) > 1
    g, r = s["GSA"], s["GRS"]
    if r["e"].size and g["sat_row"].size:  # residuals go by satellite: a satellite used twice is left to the reference
        code = _sat_code(g["sat_const"], g["sat_svid"])
        rank, n_codes = _code_ranks(code)
        counts = np.bincount(g["e"][g["sat_row"]] * n_codes + rank[code], minlength=n_epochs * n_codes)
        with_grs = np.bincount(r["e"], minlength=n_epochs) > 0
        bad |= (counts.reshape(n_epochs, n_codes) > 1).any(axis=1) & with_grs
    return bad


def _gsv_reports(e: np.ndarray, code: np.ndarray, signal: np.ndarray) -> np.ndarray:
    """Which GSV satellite rows (in line order) stand for their satellite in their epoch.

    As the reference assembler, which goes through the reports in order and replaces the kept one
    when the new signal id is lower or equal, or the kept one has none (-1): the kept report is,
    after the last report without a signal id, the last one with the lowest signal id (the report
    without one itself when it is the last). In one compiled pass where the kernels are built (a receiver
    reporting each satellite's signals apart, as a dual-frequency one does, gives every satellite several rows),
    else sorted and grouped here (:func:`_gsv_reports_numpy`, the reference the test compares the kernel with).
    """
    gsv_reports = getattr(kernels.compiled, "gsv_reports", None)
    if gsv_reports is not None and e.size:
        chosen = np.empty(e.size, np.uint8)
        as_int = [np.ascontiguousarray(x, np.int64) for x in (e, code, signal)]
        if gsv_reports(*as_int, chosen):
            return np.flatnonzero(chosen)
    return _gsv_reports_numpy(e, code, signal)


def _gsv_reports_numpy(e: np.ndarray, code: np.ndarray, signal: np.ndarray) -> np.ndarray:
    """:func:`_gsv_reports` with numpy: the rows sorted by epoch and satellite, each group's kept row picked at once."""
    m = e.size
    if m == 0:
        return np.zeros(0, np.int64)
    key = e.astype(np.int64) * (16 * 1024) + code
    order = np.argsort(key, kind="stable")
    k = key[order]
    start = np.flatnonzero(np.concatenate(([True], k[1:] != k[:-1])))
    if start.size == m:
        return np.arange(m)  # every satellite once: all rows
    size = np.diff(np.append(start, m))
    group = np.repeat(np.arange(start.size), size)
    pos = np.arange(m) - start[group]
    sig = signal[order].astype(np.int64)
    last_none = np.maximum.reduceat(np.where(sig < 0, pos, -1), start)[group]
    candidate = (pos > last_none) | ((pos == last_none) & (last_none == size[group] - 1))
    # per group, the candidate with the lowest signal id, the last of those: the least of (signal id, −place)
    span = int(size.max()) + 1
    rank = np.where(candidate, sig + 1, 1 << 20) * span + (span - 1 - pos)
    best = np.minimum.reduceat(rank, start)[group] == rank
    chosen = np.zeros(m, bool)
    chosen[order[best]] = True
    return np.flatnonzero(chosen)


def _sat_code(const: np.ndarray, svid: np.ndarray) -> np.ndarray:
    """One small int per satellite, in the satellite table's order (constellation, then number < 1024)."""
    return const.astype(np.int64) * 1024 + svid.astype(np.int64)


def _code_ranks(*codes: np.ndarray) -> tuple[np.ndarray, int]:
    """Rank of each satellite code among those present (a look-up table) and how many are present."""
    present = np.zeros(16 * 1024, bool)
    for c in codes:
        present[c] = True
    rank = np.cumsum(present) - 1
    return rank, int(present.sum())


def _altitude(n: int, gga: dict, gns: dict) -> tuple[np.ndarray, np.ndarray]:
    """Altitude and geoid separation, as the reference assembler sets them from GGAs (fix) and a GNS (fix).

    Every GGA with a fix sets each where given; the GNS sets both only while no altitude is
    set, so the order matters: the altitude is the last GGA's given one, else the GNS's; the
    separation the last GGA's given one, except where the GNS set it (no GGA altitude before
    it): then only a GGA after the GNS replaces it.
    """
    fixed = gga["quality"] != 0
    alt_given = fixed & np.isfinite(gga["alt"])
    sep_given = fixed & np.isfinite(gga["sep"])
    fix = gns["has_fix"]
    big = np.iinfo(np.int64).max
    gns_line = scatter(n, gns["e"][fix], gns["order"][fix], big, np.int64)
    na = scatter(n, gns["e"][fix], gns["alt"][fix], np.nan)
    ns = scatter(n, gns["e"][fix], gns["sep"][fix], np.nan)
    ga = last_finite(n, {"e": gga["e"][alt_given], "order": gga["order"][alt_given]}, gga["alt"][alt_given])
    first_alt_line = pick(n, [(gga, gga["order"], alt_given)], big)
    alt = np.where(np.isfinite(ga), ga, na)
    gns_sets = (gns_line < big) & (first_alt_line > gns_line) & np.isfinite(ns)
    after = sep_given & (gga["order"] > gns_line[gga["e"]])
    sep_after = pick(n, [(gga, gga["sep"], after)], np.nan, last=True)
    sep_all = pick(n, [(gga, gga["sep"], sep_given)], np.nan, last=True)
    return alt, np.where(gns_sets, np.where(np.isfinite(sep_after), sep_after, ns), sep_all)


def _dates(n: int, sources: list[tuple[dict, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Per epoch, the last date given in line order, and the last change between two given in turn (later minus earlier)."""
    e = np.concatenate([rows["e"][np.asarray(d) >= 0] for rows, d in sources])
    order = np.concatenate([rows["order"][np.asarray(d) >= 0] for rows, d in sources])
    dates = np.concatenate([np.asarray(d, np.int64)[np.asarray(d) >= 0] for _, d in sources])
    date = np.full(n, -1, np.int64)
    change = np.full(n, np.nan)
    if e.size:
        sort = np.argsort(order, kind="stable")  # epochs follow line order
        e, dates = e[sort], dates[sort]
        last = np.flatnonzero(np.append(e[1:] != e[:-1], True))
        date[e[last]] = dates[last]
        differs = np.flatnonzero((e[1:] == e[:-1]) & (dates[1:] != dates[:-1])) + 1  # in turn, ascending
        last_change = differs[np.append(e[differs][1:] != e[differs][:-1], True)] if differs.size else differs
        change[e[last_change]] = (dates[last_change] - dates[last_change - 1]).astype(float)
    return date, change


def _positions(n: int, candidates: list[tuple[dict, np.ndarray, int]]):
    """Latitude, longitude, disagreement (m) and rank of each epoch's position, folding the candidates in line order.

    As the reference assembler: a candidate of another rank than the best so far is
    measured against it (the largest distance is kept); a better rank replaces it.
    Any number of candidates of each type per epoch.
    """
    e = np.concatenate([rows["e"] for rows, _, _ in candidates])
    order = np.concatenate([rows["order"] for rows, _, _ in candidates])
    lat_all = np.concatenate([rows["lat"] for rows, _, _ in candidates])
    lon_all = np.concatenate([rows["lon"] for rows, _, _ in candidates])
    ok_all = np.concatenate([usable for _, usable, _ in candidates])
    rank_all = np.concatenate([np.full(rows["e"].size, r) for rows, _, r in candidates])
    sort = np.argsort(order, kind="stable")  # epochs follow line order
    e = e[sort]
    seq = group_seq(e)
    k = int(seq.max()) + 1 if e.size else 0
    lat = np.full((n, k), np.nan)
    lon = np.full((n, k), np.nan)
    ok = np.zeros((n, k), bool)
    rank = np.full((n, k), 99)
    cell = e * k + seq
    for grid, values in ((lat, lat_all), (lon, lon_all), (ok, ok_all), (rank, rank_all)):
        grid.ravel()[cell] = values[sort]
    best_lat, best_lon = np.full(n, np.nan), np.full(n, np.nan)
    best_rank = np.full(n, 99)
    gap_max = np.full(n, -1.0)
    for j in range(k):
        c_ok, c_lat, c_lon, c_rank = ok[:, j], lat[:, j], lon[:, j], rank[:, j]
        measure = c_ok & (best_rank < 99) & (c_rank != best_rank)
        with np.errstate(invalid="ignore"):
            gap = np.hypot((c_lat - best_lat) * 111_195.0, (c_lon - best_lon) * 111_195.0 * np.cos(np.radians(c_lat)))
            gap_max = np.where(measure & (gap > gap_max), gap, gap_max)
        better = c_ok & (c_rank < best_rank)
        best_lat = np.where(better, c_lat, best_lat)
        best_lon = np.where(better, c_lon, best_lon)
        best_rank = np.where(better, c_rank, best_rank)
    return best_lat, best_lon, np.where(gap_max >= 0, gap_max, np.nan), best_rank


def _gsa_residuals(gsa: dict, grs: dict) -> tuple[np.ndarray, np.ndarray]:
    """Which used satellites (GSA satellite rows) get a GRS residual, and its value.

    As the reference assembler: a GSA with a system id takes the epoch's first GRS of
    that system id; otherwise (or when there is none) the GRS in the same place, if it
    has no system id or the same one. Only a GRS with as many residuals as the GSA has
    satellites is used.
    """
    n_sat = gsa["sat_row"].size
    if grs["e"].size == 0 or n_sat == 0:
        return np.zeros(n_sat, bool), np.zeros(0)
    g_e, r_e = gsa["e"], grs["e"]
    g_sys, r_sys = gsa["sysid"], grs["sysid"]
    big = 1 << 20
    matched = np.full(g_e.size, -1, np.int64)
    # by system id: the first GRS of the epoch with it
    r_with = np.flatnonzero(r_sys >= 0)
    if r_with.size:
        keys, first = np.unique(r_e[r_with] * big + r_sys[r_with], return_index=True)
        want = g_e * big + g_sys
        pos = np.clip(np.searchsorted(keys, want), 0, keys.size - 1)
        found = (g_sys >= 0) & (keys[pos] == want)
        matched[found] = r_with[first[pos[found]]]
    else:
        found = np.zeros(g_e.size, bool)
    # by place in the epoch
    r_key = r_e * big + group_seq(r_e)
    g_key = g_e * big + group_seq(g_e)
    pos = np.clip(np.searchsorted(r_key, g_key), 0, r_key.size - 1)
    same_place = ~found & (r_key[pos] == g_key) & ((r_sys[pos] == -1) | (r_sys[pos] == g_sys))
    matched[same_place] = pos[same_place]
    usable = (matched >= 0) & (grs["n_res"][np.maximum(matched, 0)] == gsa["n_keys"])
    row = gsa["sat_row"]
    has = usable[row]
    values = grs["residuals"][matched[row[has]], gsa["sat_k"][has]]
    return has, values


def assemble(epoch_ids: np.ndarray, tod_s: np.ndarray, line: np.ndarray, s: dict[str, dict]) -> dict[str, np.ndarray]:
    """The epoch and satellite arrays (as :meth:`EpochAssembler.take` gives them) of supported epochs.

    ``s[type]`` holds each sentence type's decoded rows with ``e`` (the epoch's
    position in ``epoch_ids``) and ``order`` (the line index, for "which came first").
    """
    n = epoch_ids.size
    gga, rmc, vtg, gsa, gsv, gst, gll, zda, grs, gbs, gns = (s[t] for t in SENTENCE_TYPES)
    out: dict[str, np.ndarray] = {"epoch": epoch_ids.astype(np.int64), "tod_s": tod_s, "line": line.astype(np.int64)}
    floats = {k: np.full(n, np.nan) for k in FLOAT_COLUMNS}

    # GGA: quality, satellites, position (rank 0) when quality != 0, altitude, HDOP fallback
    q = pick(n, [(gga, gga["quality"].astype(np.int64), gga["quality"] >= 0)], -1, last=True)
    n_used_gga = pick(n, [(gga, gga["n_used"].astype(np.int64), gga["n_used"] >= 0)], -1, last=True)
    n_used_gga = np.where(n_used_gga >= 0, n_used_gga, scatter(n, gns["e"], gns["n_used"], -1, np.int64))  # GNS: when GGA gives none
    gga_pos = (gga["quality"] != 0) & np.isfinite(gga["lat"]) & np.isfinite(gga["lon"])
    floats["alt_m"], floats["geoid_sep_m"] = _altitude(n, gga, gns)
    hdop_gga = first_finite(n, [(gga, gga["hdop"]), (gns, gns["hdop"])])

    # RMC: position (rank 2) and velocity (rank 0) when 'A'
    active = rmc["status"] == _A
    speed = first_finite(n, [(rmc, np.where(active, rmc["speed"], np.nan))])
    course = first_finite(n, [(rmc, np.where(active, rmc["course"], np.nan))])
    # RMC and GLL: status and mode letter, the first given in line order
    status = first_given(n, [(rmc, np.where((rmc["status"] == _A) | (rmc["status"] == _V), rmc["status"], 0)),
                              (gll, np.where((gll["status"] == _A) | (gll["status"] == _V), gll["status"], 0))])  # fmt: skip
    mode = first_given(n, [(rmc, rmc["mode"]), (gll, gll["mode"]), (gns, gns["mode"])])
    # RMC and ZDA: the date, the last given; a second, different one is a disagreement
    date, floats["date_disagreement_days"] = _dates(n, [(rmc, rmc["date"]), (zda, zda["date"])])
    # position: GGA, RMC ('A'), GLL (not 'V'), the best rank wins; each later one is measured against the best so far
    candidates = [
        (gga, gga_pos, 0),
        (gns, gns["has_fix"] & np.isfinite(gns["lat"]) & np.isfinite(gns["lon"]), 1),
        (rmc, active & np.isfinite(rmc["lat"]) & np.isfinite(rmc["lon"]), 2),
        (gll, (gll["status"] != _V) & np.isfinite(gll["lat"]) & np.isfinite(gll["lon"]), 3),
    ]
    floats["lat_deg"], floats["lon_deg"], floats["pos_disagreement_m"], pos_rank = _positions(n, candidates)

    # VTG: velocity (rank 1) unless its mode is 'N'
    use = ~vtg["mode_n"]
    vtg_speed = first_finite(n, [(vtg, np.where(use, vtg["speed"], np.nan))])
    vtg_course = first_finite(n, [(vtg, np.where(use, vtg["course"], np.nan))])
    floats["speed_mps"] = np.where(np.isfinite(speed), speed, vtg_speed)
    floats["course_deg"] = np.where(np.isfinite(course), course, vtg_course)

    # GSA: DOPs (last given), fix mode (highest), satellites used
    floats["pdop"] = last_finite(n, gsa, gsa["pdop"])
    floats["vdop"] = last_finite(n, gsa, gsa["vdop"])
    hdop_gsa = last_finite(n, gsa, gsa["hdop"])
    floats["hdop"] = np.where(np.isfinite(hdop_gsa), hdop_gsa, hdop_gga)
    fix_mode = np.full(n, -1, np.int64)
    if gsa["e"].size:
        first = np.flatnonzero(np.concatenate(([True], gsa["e"][1:] != gsa["e"][:-1])))
        fix_mode[gsa["e"][first]] = np.maximum(np.maximum.reduceat(gsa["fix_mode"], first), -1)
    has_gsa = np.bincount(gsa["e"], minlength=n) > 0

    # GST
    for name in ("rms_residual_m", "sigma_major_m", "sigma_minor_m", "ellipse_orient_deg", "sigma_lat_m", "sigma_lon_m", "sigma_alt_m"):
        floats[name] = last_finite(n, gst, gst[name])

    # GBS
    for name in GBS_COLUMNS:
        floats[name] = last_finite(n, gbs, gbs[name])
    failed = pick(n, [(gbs, gbs["gbs_failed_svid"].astype(np.int64), gbs["gbs_failed_svid"] >= 0)], -1, last=True)

    # satellites: the union of GSV "in view" and GSA "used", ordered by constellation and number:
    # cells of an (epoch × satellite present in the block) grid, read in order
    view_e = gsv["e"][gsv["sat_row"]]
    view_code = _sat_code(gsv["sat_const"], gsv["sat_svid"])
    kept = _gsv_reports(view_e, view_code, gsv["sat_signal"])
    gsv = {**gsv, **{k: gsv[k][kept] for k in SAT_FIELDS if k in gsv and k != "sat_k"}}
    view_e, view_code = view_e[kept], view_code[kept]
    used_e = gsa["e"][gsa["sat_row"]]
    used_code = _sat_code(gsa["sat_const"], gsa["sat_svid"])
    rank, n_codes = _code_ranks(view_code, used_code)
    code_of_rank = np.zeros(max(n_codes, 1), np.int64)
    code_of_rank[rank[view_code]] = view_code
    code_of_rank[rank[used_code]] = used_code
    view_cell = view_e * n_codes + rank[view_code]
    used_cell = used_e * n_codes + rank[used_code]
    from_view = np.full(n * n_codes, -1, np.int64)
    from_view[view_cell] = np.arange(view_cell.size)
    used_grid = np.zeros(n * n_codes, bool)
    used_grid[used_cell] = True
    cells = np.flatnonzero((from_view >= 0) | used_grid)
    sat_epoch = cells // max(n_codes, 1)
    code = code_of_rank[cells % max(n_codes, 1)] if n_codes else cells
    used = used_grid[cells]
    vi = from_view[cells]
    v = vi >= 0
    vi = np.where(v, vi, 0)

    def seen(values, fill, dtype):
        return np.where(v, values[vi] if values.size else fill, fill).astype(dtype)

    out["sat_epoch"] = epoch_ids[sat_epoch].astype(np.int64)
    out["sat_constellation"] = (code // 1024).astype(np.int8)
    out["sat_svid"] = (code % 1024).astype(np.int16)
    out["sat_prn"] = seen(gsv["sat_prn"], -1, np.int16)
    out["sat_signal_id"] = seen(gsv["sat_signal"], -1, np.int8)
    out["sat_elev_deg"] = seen(gsv["sat_elev"], np.nan, np.float64)
    out["sat_azim_deg"] = seen(gsv["sat_azim"], np.nan, np.float64)
    out["sat_cn0_dbhz"] = seen(gsv["sat_cn0"], np.nan, np.float64)
    out["sat_used"] = used
    residual_grid = np.full(n * n_codes, np.nan)
    has, values = _gsa_residuals(gsa, grs)
    residual_grid[used_cell[has]] = values
    out["sat_residual_m"] = residual_grid[cells]
    n_in_view = np.bincount(view_e, minlength=n)
    n_used_gsa = np.bincount(sat_epoch[used], minlength=n)

    # fix validity, as assembler._fix_valid
    mode_fix = ~np.isin(mode, _NOT_FIX)
    valid = np.where(q >= 0, np.isin(q, _GGA_VALID),
                     np.where(status > 0, (status == _A) & mode_fix, np.where(fix_mode >= 0, fix_mode >= 2, mode_fix)))  # fmt: skip
    out["fix_valid"] = valid & (pos_rank < 99)
    out["date_days"] = date
    out["fix_quality"] = q.astype(np.int8)
    out["fix_mode"] = fix_mode.astype(np.int8)
    out["mode_indicator"] = _ONE_CHAR[mode]
    out["n_used"] = np.where(has_gsa, n_used_gsa, n_used_gga).astype(np.int16)
    out["n_in_view"] = np.where(np.bincount(gsv["e"], minlength=n) > 0, n_in_view, -1).astype(np.int16)
    out["gbs_failed_svid"] = failed.astype(np.int16)
    out.update(floats)
    return out
