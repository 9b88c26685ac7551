"""Decode the common sentences of a block in bulk: one function per type, arrays in, arrays out.

Each decoder takes the block (:class:`~tollcli.readers.nmea.bulk_lines.BlockLines`) and the
indices of its lines of that type, and returns a dict of arrays (one row per line)
with an ``ok`` mask. A line that is not ``ok`` is re-read by the per-line reader,
which either finds it malformed or reads it (its epoch is then assembled per line).
Fields and rules are those of :mod:`tollcli.readers.nmea.assembler`, which documents them.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from tollcli.readers.nmea import bulk_fields as bf
from tollcli.readers.nmea import kernels
from tollcli.readers.nmea.bulk_lines import BlockLines, pack_address, talker_code
from tollcli.readers.nmea.fields import KMH_MPS, KNOT_MPS
from tollcli.readers.nmea.satellite_ids import (
    CONSTELLATIONS,
    SYSTEM_ID_CONSTELLATION,
    TALKER_CONSTELLATION,
    satellite_id,
)

MAX_PRN = 1_023  # satellite numbers in the look-up table; larger ones go the per-line way
#: constellation hints, in the order of the satellite look-up table's rows
HINTS = (None, "GLONASS", "Galileo", "BeiDou", "QZSS", "NavIC")
_CONST_INDEX = {name: i for i, name in enumerate(CONSTELLATIONS)}
_A, _V = ord("A"), ord("V")


@lru_cache(maxsize=1)
def satellite_table() -> tuple[np.ndarray, np.ndarray]:
    """(constellation index, svid) of every (hint row, number 0…9999), from :func:`satellite_id`."""
    const = np.zeros((len(HINTS), MAX_PRN + 1), np.int8)
    svid = np.zeros((len(HINTS), MAX_PRN + 1), np.int64)
    for h, hint in enumerate(HINTS):
        for prn in range(1, MAX_PRN + 1):
            c, s = satellite_id(hint, prn)
            const[h, prn] = _CONST_INDEX[c]
            svid[h, prn] = s
    return const, svid


def _satellites(hint_row: np.ndarray, prn: np.ndarray) -> dict[str, np.ndarray]:
    """Constellation index and system number of each (hint row, number ≤ MAX_PRN), from :func:`satellite_table`."""
    const_t, svid_t = satellite_table()
    cell = hint_row * (MAX_PRN + 1) + prn
    return {"sat_const": const_t.ravel()[cell], "sat_svid": svid_t.ravel()[cell]}


def _hint_row(name: str | None) -> int:
    return HINTS.index(name) if name in HINTS else 0


#: talker (two packed bytes) → hint row; system id → hint row
_TALKER_ROW = {pack_address(t): _hint_row(c) for t, c in TALKER_CONSTELLATION.items()}
_SYSID_ROW = {k: _hint_row(v) for k, v in SYSTEM_ID_CONSTELLATION.items()}


def talker_rows(address: np.ndarray) -> np.ndarray:
    """Hint row of each line's talker (0, the number alone, for unknown talkers)."""
    talker = talker_code(address)
    out = np.zeros(address.size, np.int64)
    for code, row in _TALKER_ROW.items():
        out[talker == code] = row
    return out


def _span(bl: BlockLines, idx: np.ndarray, k: int):
    return bl.field_span(idx, k)


def _numbers(bl: BlockLines, idx: np.ndarray, ks: tuple[int, ...]):
    """Fields ``ks`` of lines ``idx`` read as decimals in one pass: (values, ok, empty, dotted), each (len(ks), n)."""
    lines = np.tile(idx, len(ks))
    k = np.repeat(np.asarray(ks, np.int64), idx.size)
    shape = (len(ks), idx.size)
    return tuple(a.reshape(shape) for a in bl.field_decimals(lines, k))


def _as_int(v: np.ndarray, ok: np.ndarray, empty: np.ndarray, dotted: np.ndarray, lo: int, hi: int, missing: int = -1):
    """Decimals read by :func:`_numbers` as integers in [lo, hi], as ``fields.integer`` (``int("5.0")`` fails)."""
    out = np.where(ok & ~empty, v, missing).astype(np.int64)
    return out, ok & ~dotted & (empty | ((out >= lo) & (out <= hi)))


def _letter(bl, idx, k) -> np.ndarray:
    """The field's character code when it is exactly one character, 0 when empty, -1 otherwise."""
    s, e = _span(bl, idx, k)
    n = e - s
    ch = bl.buf[np.minimum(s, bl.buf.size - 1)].astype(np.int64)
    return np.where(n == 0, 0, np.where(n == 1, ch, -1))


def _first_char(bl, idx, k) -> np.ndarray:
    """The field's first character code, 0 when empty."""
    s, e = _span(bl, idx, k)
    ch = bl.buf[np.minimum(s, bl.buf.size - 1)].astype(np.int64)
    return np.where(e > s, ch, 0)


def _latlon(bl, idx, v, ok, empty, i_lat: int, k_lat: int):
    """Latitude and longitude from rows ``i_lat``, ``i_lat + 1`` of :func:`_numbers` (fields ``k_lat``, ``k_lat + 2``)."""
    lat, ok1 = bf.ddmm_deg(v[i_lat], ok[i_lat], empty[i_lat], _letter(bl, idx, k_lat + 1), 90.0, ord("S"), ord("N"))
    lon, ok2 = bf.ddmm_deg(v[i_lat + 1], ok[i_lat + 1], empty[i_lat + 1], _letter(bl, idx, k_lat + 3), 180.0, ord("W"), ord("E"))
    return lat, lon, ok1 & ok2


def _tod(bl, idx, k=1):
    s, e = _span(bl, idx, k)
    return bf.time_of_day_s(bl, s, e)


def gga(bl: BlockLines, idx: np.ndarray) -> dict:
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    v, oks, empty, dotted = _numbers(bl, idx, (2, 4, 6, 7, 8, 9, 11))
    lat, lon, ok_pos = _latlon(bl, idx, v, oks, empty, 0, 2)
    quality, ok_q = _as_int(v[2], oks[2], empty[2], dotted[2], 0, 127)
    ok_pos |= quality == 0  # no fix: the position fields are not read (assembler._latlon)
    n_used, ok_n = _as_int(v[3], oks[3], empty[3], dotted[3], 0, 9_999)
    sep = np.where(nf > 10, v[6], np.nan)
    ok_s = oks[6] | (nf <= 10)
    return dict(tod=tod, lat=lat, lon=lon, quality=quality, n_used=n_used, hdop=v[4], alt=v[5], sep=sep,
                ok=(nf >= 9) & ok & ok_pos & ok_q & ok_n & oks[4] & oks[5] & ok_s)  # fmt: skip


#: GNS mode letters (one per constellation) that mean a fix
_GNS_FIX = np.array([ord(c) for c in "ADPRFM"])
GNS_MODE_CHARS = 8  # longer mode fields go the per-line way


def gns(bl: BlockLines, idx: np.ndarray) -> dict:
    """GNS: position, a mode letter per constellation (a fix when any is A, D, P, R, F or M), satellites, HDOP, altitude."""
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    v, oks, empty, dotted = _numbers(bl, idx, (2, 4, 7, 8, 9, 10))
    lat, lon, ok_pos = _latlon(bl, idx, v, oks, empty, 0, 2)
    n_used, ok_n = _as_int(v[2], oks[2], empty[2], dotted[2], 0, 9_999)
    sep = np.where(nf > 9, v[5], np.nan)
    s, e = _span(bl, idx, 6)
    width = e - s
    has_fix = np.zeros(idx.size, bool)
    for j in range(GNS_MODE_CHARS):
        ch = bl.buf[np.minimum(s + j, bl.buf.size - 1)]
        has_fix |= (j < width) & np.isin(ch, _GNS_FIX)
    ok_pos |= ~has_fix
    return dict(tod=tod, lat=lat, lon=lon, mode=_first_char(bl, idx, 6), has_fix=has_fix, n_used=n_used, hdop=v[3],
                alt=v[4], sep=sep, ok=(nf >= 9) & ok & ok_pos & ok_n & oks[3] & oks[4] & (oks[5] | (nf <= 9))
                & (width <= GNS_MODE_CHARS))  # fmt: skip


def rmc(bl: BlockLines, idx: np.ndarray) -> dict:
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    status = _letter(bl, idx, 2)
    v, oks, empty, _ = _numbers(bl, idx, (3, 5, 7, 8))
    lat, lon, ok_pos = _latlon(bl, idx, v, oks, empty, 0, 3)
    ok_pos |= status != _A
    s, e = _span(bl, idx, 9)
    date, ok_d = bf.rmc_date_days(bl, s, e)
    fix = status == _A  # without a fix the date is not read either (assembler._rmc)
    date, ok_d = np.where(fix, date, -1), ok_d | ~fix
    mode = np.where(nf > 11, _first_char(bl, idx, 12), 0)
    return dict(tod=tod, status=status, lat=lat, lon=lon, speed=v[2] * KNOT_MPS, course=v[3], date=date, mode=mode,
                ok=(nf >= 9) & ok & ok_pos & oks[2] & oks[3] & ok_d)  # fmt: skip


def vtg(bl: BlockLines, idx: np.ndarray) -> dict:
    """Only the NMEA 2.3+ layout (``course,T,,M,knots,N,kmh,K[,mode]``); the 1.5 layout is left to the per-line path."""
    nf = bl.n_fields[idx]
    t = _letter(bl, idx, 2)
    v, oks, _, _ = _numbers(bl, idx, (1, 5, 7))
    course, knots, kmh = v
    s, e = _span(bl, idx, 9)
    mode_n = (nf > 8) & (e - s == 1) & (bl.buf[np.clip(s, 0, bl.buf.size - 1)] == ord("N"))
    speed = np.where(np.isnan(kmh), knots * KNOT_MPS, kmh * KMH_MPS)
    return dict(course=course, speed=speed, mode_n=mode_n,
                ok=(nf >= 7) & ((t == ord("T")) | (t == 0)) & oks.all(axis=0))  # fmt: skip


GST_COLUMNS = ("rms_residual_m", "sigma_major_m", "sigma_minor_m", "ellipse_orient_deg", "sigma_lat_m", "sigma_lon_m", "sigma_alt_m")


def gst(bl: BlockLines, idx: np.ndarray) -> dict:
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    v, oks, _, _ = _numbers(bl, idx, tuple(range(2, 9)))
    out = dict(zip(GST_COLUMNS, v))
    out["tod"] = tod
    out["ok"] = ok & (nf >= 8) & oks.all(axis=0)
    return out


GBS_COLUMNS = ("gbs_err_lat_m", "gbs_err_lon_m", "gbs_err_alt_m", "gbs_p_md", "gbs_bias_m", "gbs_bias_sd_m")


def gbs(bl: BlockLines, idx: np.ndarray) -> dict:
    """GBS: expected errors, the most likely failed satellite (-1 none), its P_MD, bias and bias σ."""
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    v, oks, empty, dotted = _numbers(bl, idx, (2, 3, 4, 5, 6, 7, 8))
    svid, ok_sv = _as_int(v[3], oks[3], empty[3], dotted[3], 0, 9_999)
    out = dict(zip(GBS_COLUMNS, (v[0], v[1], v[2], v[4], v[5], v[6])))
    out.update(tod=tod, gbs_failed_svid=svid, ok=ok & (nf >= 8) & oks.all(axis=0) & ok_sv)
    return out


#: most satellite slots a GSA is read with in bulk (the standard has 12; some receivers write 24)
GSA_MAX_SLOTS = 32


def gsa(bl: BlockLines, idx: np.ndarray) -> dict:
    """GSA: mode, fix mode, satellite slots, PDOP, HDOP, VDOP and (18 fields or more, a one-digit last one) the
    NMEA 4.10 system id; any number of slots (12 in the standard, 24 or fewer from some receivers), as the
    per-line reader; satellites as (line, slot) rows."""
    nf = bl.n_fields[idx]
    last = _letter(bl, idx, np.maximum(nf, 1))
    has_sys = (nf >= 18) & (last >= ord("0")) & (last <= ord("9"))
    n_slots = nf - 5 - has_sys
    ok = (nf >= 5) & (n_slots <= GSA_MAX_SLOTS)
    sysid = np.where(has_sys, last - ord("0"), -1)
    dop = np.maximum(nf - 2 - has_sys, 1)  # the first of the three DOP fields
    ks = np.stack([np.full(idx.size, 2), dop, dop + 1, dop + 2], axis=1)
    v, oks, empty, dotted = (a.reshape(idx.size, 4).T for a in bl.field_decimals(np.repeat(idx, 4), ks.ravel()))
    fix_mode, ok_m = _as_int(v[0], oks[0], empty[0], dotted[0], 0, 127)
    pdop, hdop, vdop = v[1], v[2], v[3]
    ok &= ok_m & oks[1:].all(axis=0)
    hint = talker_rows(bl.address[idx])
    for code, row in _SYSID_ROW.items():
        hint[sysid == code] = row
    hint[(sysid >= 7)] = 0  # an unknown system id: the number decides
    slots = _gsa_slots if kernels.compiled is None else _gsa_slots_compiled  # the compiled one: a single pass
    rows, prn, k, n_keys, ok_slots = slots(bl, idx, n_slots)
    ok &= ok_slots
    safe = np.clip(prn, 0, MAX_PRN)
    return {"fix_mode": fix_mode, "pdop": pdop, "hdop": hdop, "vdop": vdop, "sysid": sysid, "ok": ok,
            "n_keys": n_keys, "sat_row": rows, "sat_k": k, **_satellites(hint[rows], safe)}  # fmt: skip


def _gsa_slots_compiled(bl: BlockLines, idx: np.ndarray, n_slots: np.ndarray):
    """:func:`_gsa_slots` by the compiled kernel."""
    room = int(np.clip(n_slots, 0, GSA_MAX_SLOTS).sum())
    prn, row, k = (np.empty(room, np.int64) for _ in range(3))
    n_keys = np.empty(idx.size, np.int64)
    ok = np.ones(idx.size, bool)
    m = kernels.compiled.gsa_slots(bl.buf, bl.first_comma, bl.end, bl.commas, np.ascontiguousarray(idx, np.int64),
                                   np.ascontiguousarray(n_slots, np.int64), prn, row, k, n_keys, ok)  # fmt: skip
    return row[:m], prn[:m], k[:m], n_keys, ok


def _gsa_slots(bl: BlockLines, idx: np.ndarray, n_slots: np.ndarray):
    """The satellites of GSA lines ``idx`` (fields 3 … 2 + n_slots): (row, PRN, place among the line's
    satellites, satellites per line, line ok: every non-empty slot a number in 1 … MAX_PRN)."""
    width = int(np.clip(n_slots, 0, GSA_MAX_SLOTS).max()) if idx.size else 0
    rows = np.repeat(np.arange(idx.size), width)
    place = np.tile(np.arange(width), idx.size)
    inside = place < n_slots[rows]
    value, ok_prn, empty, _ = bl.field_decimals(idx[rows], place + 3, integer_only=True)
    present = ~empty & inside
    prn, ok_prn = bf.as_integer(value, ok_prn, empty, lo=1, hi=9_999)
    ok_prn &= prn <= MAX_PRN  # beyond the look-up table: the per-line path
    ok = (ok_prn | ~inside).reshape(idx.size, width).all(axis=1)
    k = np.cumsum(present.reshape(idx.size, width), axis=1).ravel() - 1  # a satellite's place in its GSA's list
    return rows[present], prn[present], k[present], present.reshape(idx.size, width).sum(axis=1), ok


def gsv(bl: BlockLines, idx: np.ndarray) -> dict:
    """GSV groups as (line, group) rows; a trailing one-character hex signal id (NMEA 4.10)."""
    nf = bl.n_fields[idx]
    body = nf - 3
    has_signal = (body % 4) == 1
    ok = (nf >= 3) & ((body % 4 == 0) | has_signal)
    s, e = bl.field_span(idx, nf)
    ch = bl.buf[np.minimum(s, bl.buf.size - 1)].astype(np.int64)
    hexv = np.where((ch >= 48) & (ch <= 57), ch - 48, np.where((ch >= 65) & (ch <= 70), ch - 55, -2))
    signal = np.where(has_signal, np.where(e == s, -1, np.where(e - s == 1, hexv, -2)), -1)
    ok &= signal >= -1
    groups = np.maximum(body, 0) // 4
    read = _gsv_groups if kernels.compiled is None else _gsv_groups_compiled  # the compiled one: a single pass
    r, prn, elev, azim, cn0, ok_groups = read(bl, idx, groups)
    ok &= ok_groups
    hint = talker_rows(bl.address[idx])
    safe = np.clip(prn, 0, MAX_PRN)
    return dict(ok=ok, sat_row=r, **_satellites(hint[r], safe),
                sat_prn=prn, sat_signal=signal[r], sat_elev=elev, sat_azim=azim, sat_cn0=cn0)  # fmt: skip


def _gsv_groups_compiled(bl: BlockLines, idx: np.ndarray, groups: np.ndarray):
    """:func:`_gsv_groups` by the compiled kernel."""
    room = int(groups.sum())
    row, prn = np.empty(room, np.int64), np.empty(room, np.int64)
    elev, azim, cn0 = np.empty(room), np.empty(room), np.empty(room)
    ok = np.ones(idx.size, bool)
    m = kernels.compiled.gsv_groups(bl.buf, bl.first_comma, bl.end, bl.commas, np.ascontiguousarray(idx, np.int64),
                                    np.ascontiguousarray(groups, np.int64), row, prn, elev, azim, cn0, ok)  # fmt: skip
    return row[:m], prn[:m], elev[:m], azim[:m], cn0[:m], ok


def _gsv_groups(bl: BlockLines, idx: np.ndarray, groups: np.ndarray):
    """The satellites of GSV lines ``idx`` (``groups`` of four fields from field 4): (row, number, elevation,
    azimuth, C/N0) of each group with a number, and each line's ok (every such group one the bulk path reads)."""
    rows = np.repeat(np.arange(idx.size), groups)
    first = np.cumsum(groups) - groups
    g = np.arange(rows.size) - first[rows]
    k0 = 4 + 4 * g
    line = idx[rows]
    lines4 = np.tile(line, 4)
    v, oks, empty, dotted = bl.field_decimals(lines4, np.concatenate([k0, k0 + 1, k0 + 2, k0 + 3]))
    m = line.size
    present = ~empty[:m]
    prn, ok_prn = _as_int(v[:m], oks[:m], empty[:m], dotted[:m], 1, 9_999)
    ok_prn &= prn <= MAX_PRN
    elev, azim, cn0 = v[m : 2 * m], v[2 * m : 3 * m], v[3 * m :]
    ok_e, ok_a, ok_c = oks[m : 2 * m], oks[2 * m : 3 * m], oks[3 * m :]
    with np.errstate(invalid="ignore"):
        ok_range = (np.isnan(elev) | ((elev >= -90.0) & (elev <= 90.0))) & (np.isnan(azim) | ((azim >= 0.0) & (azim <= 360.0)))
    sat_ok = ~present | (ok_prn & ok_e & ok_a & ok_c & ok_range)
    ok = np.bincount(rows[~sat_ok], minlength=idx.size) == 0
    keep = present
    return rows[keep], prn[keep], elev[keep], azim[keep], cn0[keep], ok


def gll(bl: BlockLines, idx: np.ndarray) -> dict:
    """GLL: position, then (NMEA 2.3+) time, status and mode."""
    nf = bl.n_fields[idx]
    v, oks, empty, _ = _numbers(bl, idx, (1, 3))
    lat, lon, ok_pos = _latlon(bl, idx, v, oks, empty, 0, 1)
    tod, ok_t = _tod(bl, idx, 5)
    tod = np.where(nf > 4, tod, np.nan)
    status = np.where(nf > 5, _letter(bl, idx, 6), 0)
    ok_pos |= status == _V
    mode = np.where(nf > 6, _first_char(bl, idx, 7), 0)
    return {"tod": tod, "lat": lat, "lon": lon, "status": status, "mode": mode,
            "ok": (nf >= 4) & ok_pos & (ok_t | (nf <= 4))}  # fmt: skip


def zda(bl: BlockLines, idx: np.ndarray) -> dict:
    """ZDA: time and date (read only when day, month and year are all given, as the per-line reader does)."""
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    v, oks, empty, dotted = _numbers(bl, idx, (2, 3, 4))
    given = ~empty.any(axis=0)
    day, ok_d = _as_int(v[0], oks[0], empty[0], dotted[0], 1, 31)
    month, ok_m = _as_int(v[1], oks[1], empty[1], dotted[1], 1, 12)
    year, ok_y = _as_int(v[2], oks[2], empty[2], dotted[2], 1, 9_999)
    valid = ok_d & ok_m & ok_y & (day <= bf.days_in_month(year, month))
    date = np.where(given & valid, bf.days_from_civil(year, month, day), -1)
    return {"tod": tod, "date": date, "ok": (nf >= 4) & ok & (~given | valid)}


GRS_SLOTS = 14


def grs(bl: BlockLines, idx: np.ndarray) -> dict:
    """GRS: time, residuals in the order of the satellites of the GSA they go with, NMEA 4.10 system id.

    As the per-line reader: fourteen fields after the mode are twelve residuals, the
    system id and the signal id; otherwise all are residuals; empty trailing ones are dropped.
    """
    nf = bl.n_fields[idx]
    tod, ok = _tod(bl, idx)
    body = nf - 2
    ok &= (nf >= 3) & (body <= GRS_SLOTS)
    n_slots = np.where(body == 14, 12, np.clip(body, 0, GRS_SLOTS))
    v, oks, empty, _ = _numbers(bl, idx, tuple(range(3, 3 + GRS_SLOTS)))
    inside = np.arange(GRS_SLOTS)[:, None] < n_slots[None, :]
    ok &= (oks | ~inside).all(axis=0)
    values = np.where(inside, v, np.nan)
    given = inside & ~empty
    n_res = np.where(given.any(axis=0), GRS_SLOTS - np.argmax(given[::-1], axis=0), 0)
    s, e = _span(bl, idx, 15)
    sys_value, ok_sys = bf.integer(bl, s, e)
    has_sys = (body == 14) & (e > s)
    ok &= ok_sys | (body != 14)
    return {"tod": tod, "ok": ok, "sysid": np.where(has_sys, sys_value, -1), "n_res": n_res, "residuals": values.T.copy()}
