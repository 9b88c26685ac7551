"""Assemble epochs from sentences decoded in bulk, with the rules of :mod:`tollcli.readers.nmea.assembler`.

The bulk path assembles the common epoch: at most one GGA, GNS, RMC, VTG, GST, GBS, GLL and
ZDA, any number of GSA and GSV (a satellite reported on several signals keeps its
report as the reference assembler chooses it). Epochs outside that
(:func:`unsupported_epochs`) are assembled per line by the reference assembler.
Every function here works on all epochs of a block at once.
"""

from __future__ import annotations

import numpy as np

from tollcli.readers.nmea.assembler import FLOAT_COLUMNS
from tollcli.readers.nmea.bulk_sentences import GBS_COLUMNS
from tollcli.readers.nmea.satellite_ids import CONSTELLATIONS

SENTENCE_TYPES = ("GGA", "RMC", "VTG", "GSA", "GSV", "GST", "GLL", "ZDA", "GRS", "GBS", "GNS")
SAT_FIELDS = ("sat_row", "sat_k", "sat_const", "sat_svid", "sat_prn", "sat_signal", "sat_elev", "sat_azim", "sat_cn0")
_A, _V = ord("A"), ord("V")
_NOT_FIX = np.array([ord(c) for c in "ENMS"])
_GGA_VALID = (1, 2, 3, 4, 5)
_CONSTELLATION_NAMES = np.array(CONSTELLATIONS, dtype=object)
_ONE_CHAR = np.array([""] + [chr(i) for i in range(1, 256)], dtype=object)


def subset(decoded: dict, keep: np.ndarray) -> dict:
    """The decoded rows where ``keep`` holds (satellite rows follow their sentence)."""
    if keep.all():
        return dict(decoded)
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
    """Epochs the bulk rules do not cover: a repeated GGA/GNS/RMC/VTG/GST/GBS/GLL/ZDA, or a GRS with a satellite used twice."""
    bad = np.zeros(n_epochs, bool)
    for t in ("GGA", "GNS", "RMC", "VTG", "GST", "GBS", "GLL", "ZDA"):
        bad |= np.bincount(s[t]["e"], minlength=n_epochs) > 1
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
    without one itself when it is the last).
    """
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
    pick = np.lexsort((-pos, np.where(candidate, sig, 1 << 20), group))
    first = np.flatnonzero(np.concatenate(([True], group[pick][1:] != group[pick][:-1])))
    return np.sort(order[pick[first]])


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


def _scatter(n: int, e: np.ndarray, values: np.ndarray, fill, dtype=None) -> np.ndarray:
    out = np.full(n, fill, dtype=dtype or np.asarray(values).dtype)
    out[e] = values
    return out


def _last_finite(n: int, e: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per epoch, the last finite value in line order (NaN when none); ``e`` is non-decreasing."""
    fin = np.isfinite(values)
    e, values = e[fin], values[fin]
    out = np.full(n, np.nan)
    if e.size:
        last = np.flatnonzero(np.append(e[1:] != e[:-1], True))
        out[e[last]] = values[last]
    return out


def _by_epoch(n: int, rows: dict, values: np.ndarray, fill) -> tuple[np.ndarray, np.ndarray]:
    """One sentence type's values and line per epoch (at most one per epoch; ``fill`` and a huge line elsewhere)."""
    v = np.full(n, fill, dtype=np.asarray(values).dtype)
    v[rows["e"]] = values
    line = np.full(n, np.iinfo(np.int64).max, np.int64)
    line[rows["e"]] = rows["order"]
    return v, line


def _first_given(n: int, sources: list[tuple[dict, np.ndarray]]) -> np.ndarray:
    """Per epoch, the first non-zero code in line order among the sources (0 when none)."""
    out = np.zeros(n, np.int64)
    first_line = np.full(n, np.iinfo(np.int64).max, np.int64)
    for rows, values in sources:
        v, line = _by_epoch(n, rows, np.asarray(values, np.int64), 0)
        take = (v != 0) & (line < first_line)
        out = np.where(take, v, out)
        first_line = np.where(take, line, first_line)
    return out


def _first_finite(n: int, sources: list[tuple[dict, np.ndarray]]) -> np.ndarray:
    """Per epoch, the first finite value in line order among the sources (NaN when none)."""
    out = np.full(n, np.nan)
    first_line = np.full(n, np.iinfo(np.int64).max, np.int64)
    for rows, values in sources:
        v, line = _by_epoch(n, rows, np.asarray(values, float), np.nan)
        take = np.isfinite(v) & (line < first_line)
        out = np.where(take, v, out)
        first_line = np.where(take, line, first_line)
    return out


def _altitude(n: int, gga: dict, gns: dict) -> tuple[np.ndarray, np.ndarray]:
    """Altitude and geoid separation, as the reference assembler sets them from GGA (fix) and GNS (fix).

    GGA sets both (each where given); GNS sets both only while no altitude is set, so its order matters.
    """
    fixed = gga["quality"] != 0
    ga, g_line = _by_epoch(n, {"e": gga["e"][fixed], "order": gga["order"][fixed]}, gga["alt"][fixed], np.nan)
    gs, _ = _by_epoch(n, {"e": gga["e"][fixed], "order": gga["order"][fixed]}, gga["sep"][fixed], np.nan)
    fix = gns["has_fix"]
    na, n_line = _by_epoch(n, {"e": gns["e"][fix], "order": gns["order"][fix]}, gns["alt"][fix], np.nan)
    ns, _ = _by_epoch(n, {"e": gns["e"][fix], "order": gns["order"][fix]}, gns["sep"][fix], np.nan)
    has_gns = n_line < np.iinfo(np.int64).max
    gns_first = has_gns & (n_line < g_line)
    gga_first = ~gns_first
    alt = np.where(np.isfinite(ga), ga, np.where(has_gns, na, np.nan))
    # GNS first: GGA's separation where given, else GNS's; GGA first: GNS's only when GGA gave no altitude
    sep_after_gns = np.where(np.isfinite(gs), gs, ns)
    sep_after_gga = np.where(has_gns & ~np.isfinite(ga) & np.isfinite(ns), ns, gs)
    return alt, np.where(gga_first, sep_after_gga, sep_after_gns)


def _dates(n: int, sources: list[tuple[dict, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Per epoch, the last date given in line order, and the later minus the earlier one when two differ."""
    (a_rows, a_date), (b_rows, b_date) = sources
    a, a_line = _by_epoch(n, a_rows, np.asarray(a_date, np.int64), -1)
    b, b_line = _by_epoch(n, b_rows, np.asarray(b_date, np.int64), -1)
    b_later = b_line > a_line
    first, last = np.where(b_later, a, b), np.where(b_later, b, a)
    date = np.where(last >= 0, last, first)
    differ = (first >= 0) & (last >= 0) & (first != last)
    return date, np.where(differ, (last - first).astype(float), np.nan)


def _positions(n: int, candidates: list[tuple[dict, np.ndarray, int]]):
    """Latitude, longitude, disagreement (m) and rank of each epoch's position, folding the candidates in line order.

    As the reference assembler: a candidate of another rank than the best so far is
    measured against it (the largest distance is kept); a better rank replaces it.
    """
    k = len(candidates)
    lat = np.full((n, k), np.nan)
    lon = np.full((n, k), np.nan)
    ok = np.zeros((n, k), bool)
    line = np.full((n, k), np.iinfo(np.int64).max, np.int64)
    rank = np.array([c[2] for c in candidates])
    for j, (rows, usable, _) in enumerate(candidates):
        lat[rows["e"], j], lon[rows["e"], j] = rows["lat"], rows["lon"]
        ok[rows["e"], j] = usable
        line[rows["e"], j] = rows["order"]
    order = np.argsort(line, axis=1, kind="stable")
    best_lat, best_lon = np.full(n, np.nan), np.full(n, np.nan)
    best_rank = np.full(n, 99)
    gap_max = np.full(n, -1.0)
    for j in range(k):
        c = order[:, j]
        c_ok = np.take_along_axis(ok, c[:, None], 1)[:, 0]
        c_lat = np.take_along_axis(lat, c[:, None], 1)[:, 0]
        c_lon = np.take_along_axis(lon, c[:, None], 1)[:, 0]
        c_rank = rank[c]
        measure = c_ok & (best_rank < 99) & (c_rank != best_rank)
        with np.errstate(invalid="ignore"):
            gap = np.hypot((c_lat - best_lat) * 111_195.0, (c_lon - best_lon) * 111_195.0 * np.cos(np.radians(c_lat)))
            gap_max = np.where(measure & (gap > gap_max), gap, gap_max)
        better = c_ok & (c_rank < best_rank)
        best_lat = np.where(better, c_lat, best_lat)
        best_lon = np.where(better, c_lon, best_lon)
        best_rank = np.where(better, c_rank, best_rank)
    return best_lat, best_lon, np.where(gap_max >= 0, gap_max, np.nan), best_rank


def _group_seq(e: np.ndarray) -> np.ndarray:
    """Each row's place among the rows of its epoch (``e`` non-decreasing)."""
    return np.arange(e.size) - np.searchsorted(e, e, side="left")


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
    r_key = r_e * big + _group_seq(r_e)
    g_key = g_e * big + _group_seq(g_e)
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
    q = _scatter(n, gga["e"], gga["quality"], -1, np.int64)
    n_used_gga = _scatter(n, gga["e"], gga["n_used"], -1, np.int64)
    n_used_gga = np.where(n_used_gga >= 0, n_used_gga, _scatter(n, gns["e"], gns["n_used"], -1, np.int64))  # GNS: when GGA gives none
    gga_pos = (gga["quality"] != 0) & np.isfinite(gga["lat"]) & np.isfinite(gga["lon"])
    floats["alt_m"], floats["geoid_sep_m"] = _altitude(n, gga, gns)
    hdop_gga = _first_finite(n, [(gga, gga["hdop"]), (gns, gns["hdop"])])

    # RMC: position (rank 2) and velocity (rank 0) when 'A'
    active = rmc["status"] == _A
    speed = _scatter(n, rmc["e"][active], rmc["speed"][active], np.nan)
    course = _scatter(n, rmc["e"][active], rmc["course"][active], np.nan)
    # RMC and GLL: status and mode letter, the first given in line order
    status = _first_given(n, [(rmc, np.where((rmc["status"] == _A) | (rmc["status"] == _V), rmc["status"], 0)),
                              (gll, np.where((gll["status"] == _A) | (gll["status"] == _V), gll["status"], 0))])  # fmt: skip
    mode = _first_given(n, [(rmc, rmc["mode"]), (gll, gll["mode"]), (gns, gns["mode"])])
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
    vtg_speed = _scatter(n, vtg["e"][use], vtg["speed"][use], np.nan)
    vtg_course = _scatter(n, vtg["e"][use], vtg["course"][use], np.nan)
    floats["speed_mps"] = np.where(np.isfinite(speed), speed, vtg_speed)
    floats["course_deg"] = np.where(np.isfinite(course), course, vtg_course)

    # GSA: DOPs (last given), fix mode (highest), satellites used
    floats["pdop"] = _last_finite(n, gsa["e"], gsa["pdop"])
    floats["vdop"] = _last_finite(n, gsa["e"], gsa["vdop"])
    hdop_gsa = _last_finite(n, gsa["e"], gsa["hdop"])
    floats["hdop"] = np.where(np.isfinite(hdop_gsa), hdop_gsa, hdop_gga)
    fix_mode = np.full(n, -1, np.int64)
    if gsa["e"].size:
        first = np.flatnonzero(np.concatenate(([True], gsa["e"][1:] != gsa["e"][:-1])))
        fix_mode[gsa["e"][first]] = np.maximum(np.maximum.reduceat(gsa["fix_mode"], first), -1)
    has_gsa = np.bincount(gsa["e"], minlength=n) > 0

    # GST
    for name in ("rms_residual_m", "sigma_major_m", "sigma_minor_m", "ellipse_orient_deg", "sigma_lat_m", "sigma_lon_m", "sigma_alt_m"):
        floats[name] = _scatter(n, gst["e"], gst[name], np.nan)

    # GBS
    for name in GBS_COLUMNS:
        floats[name] = _scatter(n, gbs["e"], gbs[name], np.nan)
    failed = _scatter(n, gbs["e"], gbs["gbs_failed_svid"], -1, np.int64)

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

    def pick(values, fill, dtype):
        return np.where(v, values[vi] if values.size else fill, fill).astype(dtype)

    out["sat_epoch"] = epoch_ids[sat_epoch].astype(np.int64)
    out["sat_constellation"] = _CONSTELLATION_NAMES[code // 1024]
    out["sat_svid"] = (code % 1024).astype(np.int16)
    out["sat_prn"] = pick(gsv["sat_prn"], -1, np.int16)
    out["sat_signal_id"] = pick(gsv["sat_signal"], -1, np.int8)
    out["sat_elev_deg"] = pick(gsv["sat_elev"], np.nan, np.float64)
    out["sat_azim_deg"] = pick(gsv["sat_azim"], np.nan, np.float64)
    out["sat_cn0_dbhz"] = pick(gsv["sat_cn0"], np.nan, np.float64)
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
