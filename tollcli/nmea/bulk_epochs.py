"""Assemble epochs from sentences decoded in bulk, with the rules of :mod:`tollcli.nmea.assembler`.

The bulk path assembles the common epoch: at most one GGA, RMC, VTG and GST, any
number of GSA and GSV, each satellite reported once per epoch. Epochs outside that
(:func:`unsupported_epochs`) are assembled per line by the reference assembler.
Every function here works on all epochs of a block at once.
"""

from __future__ import annotations

import numpy as np

from tollcli.nmea.assembler import FLOAT_COLUMNS
from tollcli.nmea.satellite_ids import CONSTELLATIONS

SENTENCE_TYPES = ("GGA", "RMC", "VTG", "GSA", "GSV", "GST")
SAT_FIELDS = ("sat_row", "sat_const", "sat_svid", "sat_prn", "sat_signal", "sat_elev", "sat_azim", "sat_cn0")
_A, _V = ord("A"), ord("V")
_NOT_FIX = np.array([ord(c) for c in "ENMS"])
_GGA_VALID = (1, 2, 3, 4, 5)
_CONSTELLATION_NAMES = np.array(CONSTELLATIONS, dtype=object)
_ONE_CHAR = np.array([""] + [chr(i) for i in range(1, 256)], dtype=object)


def subset(decoded: dict, keep: np.ndarray) -> dict:
    """The decoded rows where ``keep`` holds (satellite rows follow their sentence)."""
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
    """Epochs the bulk rules do not cover: a repeated GGA/RMC/VTG/GST or a satellite twice in GSV."""
    bad = np.zeros(n_epochs, bool)
    for t in ("GGA", "RMC", "VTG", "GST"):
        bad |= np.bincount(s[t]["e"], minlength=n_epochs) > 1
    g = s["GSV"]
    if g["sat_row"].size:
        code = _sat_code(g["sat_const"], g["sat_svid"])
        rank, n_codes = _code_ranks(code)
        counts = np.bincount(g["e"][g["sat_row"]] * n_codes + rank[code], minlength=n_epochs * n_codes)
        bad |= (counts.reshape(n_epochs, n_codes) > 1).any(axis=1)
    return bad


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


def assemble(epoch_ids: np.ndarray, tod_s: np.ndarray, date_days_unused, line: np.ndarray, s: dict[str, dict]) -> dict[str, np.ndarray]:
    """The epoch and satellite arrays (as :meth:`EpochAssembler.take` gives them) of supported epochs.

    ``s[type]`` holds each sentence type's decoded rows with ``e`` (the epoch's
    position in ``epoch_ids``) and ``order`` (the line index, for "which came first").
    """
    n = epoch_ids.size
    gga, rmc, vtg, gsa, gsv, gst = (s[t] for t in SENTENCE_TYPES)
    out: dict[str, np.ndarray] = {"epoch": epoch_ids.astype(np.int64), "tod_s": tod_s, "line": line.astype(np.int64)}
    floats = {k: np.full(n, np.nan) for k in FLOAT_COLUMNS}

    # GGA: quality, satellites, position (rank 0) when quality != 0, altitude, HDOP fallback
    q = _scatter(n, gga["e"], gga["quality"], -1, np.int64)
    n_used_gga = _scatter(n, gga["e"], gga["n_used"], -1, np.int64)
    gga_pos = (gga["quality"] != 0) & np.isfinite(gga["lat"]) & np.isfinite(gga["lon"])
    has_gga_pos = _scatter(n, gga["e"], gga_pos, False, bool)
    gga_lat = _scatter(n, gga["e"], gga["lat"], np.nan)
    gga_lon = _scatter(n, gga["e"], gga["lon"], np.nan)
    gga_line = _scatter(n, gga["e"], gga["order"], -1, np.int64)
    fixed = gga["quality"] != 0
    floats["alt_m"] = _scatter(n, gga["e"][fixed], gga["alt"][fixed], np.nan)
    floats["geoid_sep_m"] = _scatter(n, gga["e"][fixed], gga["sep"][fixed], np.nan)
    hdop_gga = _scatter(n, gga["e"], gga["hdop"], np.nan)

    # RMC: date, status, mode letter; position (rank 2) and velocity (rank 0) when 'A'
    date = _scatter(n, rmc["e"], rmc["date"], -1, np.int64)
    status = _scatter(n, rmc["e"], np.where((rmc["status"] == _A) | (rmc["status"] == _V), rmc["status"], 0), 0, np.int64)
    mode = _scatter(n, rmc["e"], rmc["mode"], 0, np.int64)
    active = rmc["status"] == _A
    rmc_pos = active & np.isfinite(rmc["lat"]) & np.isfinite(rmc["lon"])
    has_rmc_pos = _scatter(n, rmc["e"], rmc_pos, False, bool)
    rmc_lat = _scatter(n, rmc["e"], rmc["lat"], np.nan)
    rmc_lon = _scatter(n, rmc["e"], rmc["lon"], np.nan)
    rmc_line = _scatter(n, rmc["e"], rmc["order"], -1, np.int64)
    speed = _scatter(n, rmc["e"][active], rmc["speed"][active], np.nan)
    course = _scatter(n, rmc["e"][active], rmc["course"][active], np.nan)

    # position: GGA wins; with both, how far apart (measured with the later sentence's latitude)
    floats["lat_deg"] = np.where(has_gga_pos, gga_lat, np.where(has_rmc_pos, rmc_lat, np.nan))
    floats["lon_deg"] = np.where(has_gga_pos, gga_lon, np.where(has_rmc_pos, rmc_lon, np.nan))
    both = has_gga_pos & has_rmc_pos
    later_lat = np.where(rmc_line > gga_line, rmc_lat, gga_lat)
    dn = (rmc_lat - gga_lat) * 111_195.0
    de = (rmc_lon - gga_lon) * 111_195.0 * np.cos(np.radians(later_lat))
    with np.errstate(invalid="ignore"):
        floats["pos_disagreement_m"] = np.where(both, np.hypot(dn, de), np.nan)
    pos_rank = np.where(has_gga_pos, 0, np.where(has_rmc_pos, 2, 99))

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

    # satellites: the union of GSV "in view" and GSA "used", ordered by constellation and number:
    # cells of an (epoch × satellite present in the block) grid, read in order
    view_e = gsv["e"][gsv["sat_row"]]
    view_code = _sat_code(gsv["sat_const"], gsv["sat_svid"])
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
    out["sat_residual_m"] = np.full(cells.size, np.nan)
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
    out["n_in_view"] = n_in_view.astype(np.int16)
    out["gbs_failed_svid"] = np.full(n, -1, np.int16)
    out.update(floats)
    return out
