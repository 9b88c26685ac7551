"""Galileo I/NAV pages (Galileo OS SIS ICD §4.3.5) ↔ broadcast ephemerides, vectorized over pages.

A u-blox ``RXM-SFRBX`` from Galileo E1-B or E5b-I (``gnssId`` 2, ``sigId`` 1 or 5) holds one nominal page
pair as eight 32-bit words, most significant bit first: the even part (120 bits) in words 0–3, the odd
part in words 4–7 (some firmware appends a ninth word, ignored). Each part starts with its even/odd bit
and page type. The 128-bit *word* is the even part's 112 data bits followed by the odd part's 16; its
first six bits are the word type. A page pair counts only when it is a nominal pair (even then odd, page
type 0) and its CRC-24Q — over 4 zero bits, the even part's first 114 bits and the odd part's first 82 —
matches the 24 bits that follow them in the odd part.

:func:`decode_pages` gives per page the validity, word type and the raw integer fields of word types
0–5 (ICD Tables 40–45); :func:`ephemerides` joins word types 1–4 of one issue of data (IODnav) with the
satellite's word type 5 (health, BGD, week) into ephemerides with the RINEX field names and units of
:mod:`tollcli.gnss.orbits`; :func:`encode_pages` is the inverse, for round trips and simulated receivers.
Galileo system time is aligned with GPS weeks: GPS week = GST week number + 1024 (modulo 4096).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.lnav_subframes import PI_GPS, read_bits
from tollcli.gnss.orbits import WEEK_S
from tollcli.readers.ubx import last_of_each, subframe_words

#: GST week 0 is GPS week 1024 (1999-08-22)
GST_WEEK_OFFSET = 1024
CRC24Q_POLY = 0x1864CFB
#: (name, word type, first bit in the 128-bit word, bits, signed, scale, semicircles) — ICD Tables 40–45
FIELDS = (
    ("IODnav", 1, 6, 10, False, 1.0, False), ("toe", 1, 16, 14, False, 60.0, False),
    ("M0", 1, 30, 32, True, 2.0**-31, True), ("e", 1, 62, 32, False, 2.0**-33, False),
    ("sqrtA", 1, 94, 32, False, 2.0**-19, False),
    ("IODnav2", 2, 6, 10, False, 1.0, False), ("Omega0", 2, 16, 32, True, 2.0**-31, True),
    ("i0", 2, 48, 32, True, 2.0**-31, True), ("omega", 2, 80, 32, True, 2.0**-31, True),
    ("IDOT", 2, 112, 14, True, 2.0**-43, True),
    ("IODnav3", 3, 6, 10, False, 1.0, False), ("Omegad", 3, 16, 24, True, 2.0**-43, True),
    ("deltan", 3, 40, 16, True, 2.0**-43, True), ("Cuc", 3, 56, 16, True, 2.0**-29, False),
    ("Cus", 3, 72, 16, True, 2.0**-29, False), ("Crc", 3, 88, 16, True, 2.0**-5, False),
    ("Crs", 3, 104, 16, True, 2.0**-5, False), ("SISA", 3, 120, 8, False, 1.0, False),
    ("IODnav4", 4, 6, 10, False, 1.0, False), ("SVID", 4, 16, 6, False, 1.0, False),
    ("Cic", 4, 22, 16, True, 2.0**-29, False), ("Cis", 4, 38, 16, True, 2.0**-29, False),
    ("toc", 4, 54, 14, False, 60.0, False), ("af0", 4, 68, 31, True, 2.0**-34, False),
    ("af1", 4, 99, 21, True, 2.0**-46, False), ("af2", 4, 120, 6, True, 2.0**-59, False),
    ("BGD_E1E5a", 5, 47, 10, True, 2.0**-32, False), ("BGD_E1E5b", 5, 57, 10, True, 2.0**-32, False),
    ("E5b_HS", 5, 67, 2, False, 1.0, False), ("E1b_HS", 5, 69, 2, False, 1.0, False),
    ("E5b_DVS", 5, 71, 1, False, 1.0, False), ("E1b_DVS", 5, 72, 1, False, 1.0, False),
    ("WN", 5, 73, 12, False, 1.0, False), ("TOW", 5, 85, 20, False, 1.0, False),
    ("time_f", 0, 6, 2, False, 1.0, False), ("WN0", 0, 96, 12, False, 1.0, False), ("TOW0", 0, 108, 20, False, 1.0, False),
)  # fmt: skip
#: ephemeris field (RINEX name) ← I/NAV field
RINEX_NAMES = {"SVclockBias": "af0", "SVclockDrift": "af1", "SVclockDriftRate": "af2", "Crs": "Crs", "DeltaN": "deltan",
               "M0": "M0", "Cuc": "Cuc", "Eccentricity": "e", "Cus": "Cus", "sqrtA": "sqrtA", "Cic": "Cic",
               "Omega0": "Omega0", "Cis": "Cis", "Io": "i0", "Crc": "Crc", "omega": "omega", "OmegaDot": "Omegad",
               "IDOT": "IDOT", "BGDe5a": "BGD_E1E5a", "BGDe5b": "BGD_E1E5b"}  # fmt: skip
_SCALE = {name: s * (PI_GPS if semi else 1.0) for name, _, _, _, _, s, semi in FIELDS}


def _crc_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.int64)
    for byte in range(256):
        crc = byte << 16
        for _ in range(8):
            crc = (crc << 1) ^ (CRC24Q_POLY if crc & 0x800000 else 0)
        table[byte] = crc & 0xFFFFFF
    return table


_CRC_TABLE = _crc_table()


def crc24q(bits: np.ndarray) -> np.ndarray:
    """CRC-24Q of each row of ``bits`` (n, 8·m), vectorized over rows (a loop over the m bytes only)."""
    bytes_ = np.packbits(bits.astype(np.uint8), axis=1).astype(np.int64)
    crc = np.zeros(len(bits), dtype=np.int64)
    for k in range(bytes_.shape[1]):
        crc = ((crc << 8) & 0xFFFFFF) ^ _CRC_TABLE[((crc >> 16) ^ bytes_[:, k]) & 0xFF]
    return crc


def page_bits(words: np.ndarray) -> np.ndarray:
    """(n, ≥8) 32-bit words → (n, 256) bits (the first eight words, most significant bit first)."""
    w = np.asarray(words, dtype=np.uint64)[:, :8]
    shifts = np.arange(31, -1, -1, dtype=np.uint64)
    return ((w[..., None] >> shifts) & np.uint64(1)).astype(np.uint8).reshape(len(w), 256)


def _crc_input(bits: np.ndarray) -> np.ndarray:
    """The 200 bits the CRC covers: 4 zeros, even part bits 0–113, odd part bits 0–81."""
    return np.hstack([np.zeros((len(bits), 4), np.uint8), bits[:, :114], bits[:, 128 : 128 + 82]])


def decode_pages(words: np.ndarray) -> pd.DataFrame:
    """Per page pair: ``valid`` (nominal even/odd pair with a matching CRC-24Q), ``word_type`` and the raw
    integer fields of :data:`FIELDS` (fields of other word types are 0)."""
    bits = page_bits(words)
    nominal = (bits[:, 0] == 0) & (bits[:, 1] == 0) & (bits[:, 128] == 1) & (bits[:, 129] == 0)
    crc_ok = crc24q(_crc_input(bits)) == read_bits(bits, 128 + 82, 24, False)
    word = np.hstack([bits[:, 2:114], bits[:, 130:146]])
    kind = read_bits(word, 0, 6, False)
    out = {"valid": nominal & crc_ok, "word_type": kind}
    for name, wt, start, n, signed, _, _ in FIELDS:
        out[name] = np.where(kind == wt, read_bits(word, start, n, signed), 0)
    return pd.DataFrame(out)


def ephemerides(pages: pd.DataFrame) -> pd.DataFrame:
    """Galileo ephemerides from I/NAV page pairs (``sv`` and ``words`` columns, in log order), one per
    (satellite, IODnav).

    Word types 1–4 of the same IODnav form the orbit and clock; the satellite's word type 5 nearest in the
    log (by the pages' ``message`` numbers, else their rows) gives health (RINEX 3 bit layout: E1-B DVS bit 0, HS bits 1–2; E5b DVS bit 6, HS bits 7–8), the
    group delays and the week. An ephemeris without a word type 5 of its satellite is not produced (its
    health is unknown). Columns: those of :func:`tollcli.gnss.lnav_subframes.ephemerides` plus
    ``BGDe5a``/``BGDe5b``; ``group_delay_s`` is BGD(E1, E5b), the single-frequency E1 correction of I/NAV.
    """
    columns = ["sv", "toc_s", "toe_s", "group_delay_s", "health", "iode", *RINEX_NAMES, "Toe"]
    if pages.empty:
        return pd.DataFrame(columns=columns)
    dec = decode_pages(subframe_words(pages, 8)[0].astype(np.uint64))
    dec["sv"] = pages["sv"].to_numpy(str)
    dec["order"] = _order(pages)
    dec = dec[dec["valid"]]
    keep = {1: ["toe", "M0", "e", "sqrtA"], 2: ["Omega0", "i0", "omega", "IDOT"],
            3: ["Omegad", "deltan", "Cuc", "Cus", "Crc", "Crs"], 4: ["Cic", "Cis", "toc", "af0", "af1", "af2"]}  # fmt: skip
    iod = {1: "IODnav", 2: "IODnav2", 3: "IODnav3", 4: "IODnav4"}
    parts = [dec[dec["word_type"] == wt].assign(iode=lambda t, c=iod[wt]: t[c])[["sv", "iode", "order", *keep[wt]]]
             .drop_duplicates(["sv", "iode"], keep="last") for wt in (1, 2, 3, 4)]  # fmt: skip
    joined = parts[0]
    for part in parts[1:]:
        joined = joined.merge(part.drop(columns="order"), on=["sv", "iode"])
    five = dec[dec["word_type"] == 5][["sv", "order", "BGD_E1E5a", "BGD_E1E5b", "E5b_HS", "E1b_HS", "E5b_DVS", "E1b_DVS",
                                        "WN", "TOW"]].sort_values("order")  # fmt: skip
    if joined.empty or five.empty:
        return pd.DataFrame(columns=columns)
    joined = pd.merge_asof(joined.sort_values("order"), five, on="order", by="sv", direction="nearest").dropna(subset=["WN"])
    if joined.empty:
        return pd.DataFrame(columns=columns)
    eph = pd.DataFrame({"sv": joined["sv"].to_numpy(str), "iode": joined["iode"].to_numpy(np.int64)})
    for rinex, field in RINEX_NAMES.items():
        eph[rinex] = joined[field].to_numpy(np.int64) * _SCALE[field]
    t_now = (joined["WN"].to_numpy(float) + GST_WEEK_OFFSET) * WEEK_S + joined["TOW"].to_numpy(float)
    eph["Toe"] = joined["toe"].to_numpy(np.int64) * 60.0
    eph["toe_s"] = _nearest_week(eph["Toe"].to_numpy(), t_now)
    eph["toc_s"] = _nearest_week(joined["toc"].to_numpy(np.int64) * 60.0, t_now)
    eph["group_delay_s"] = eph["BGDe5b"]
    eph["health"] = (joined["E1b_DVS"].to_numpy(np.int64) | joined["E1b_HS"].to_numpy(np.int64) << 1
                     | joined["E5b_DVS"].to_numpy(np.int64) << 6 | joined["E5b_HS"].to_numpy(np.int64) << 7)  # fmt: skip
    return eph[columns].reset_index(drop=True)


def _order(pages: pd.DataFrame) -> np.ndarray:
    """Where each page is in the log: its ``message`` number (a sifted table's pages keep theirs), else its row."""
    return pages["message"].to_numpy(np.int64) if "message" in pages else np.arange(len(pages))


def kept(pages: pd.DataFrame) -> np.ndarray:
    """(n,) the pages of ``pages`` (as :func:`ephemerides` takes them, in log order) that can still change its result,
    whatever pages follow: of the valid ones, the last word type 1–4 of each satellite and IODnav (the ones
    :func:`ephemerides` joins), and of word type 5 the satellite's last and those nearest before and after each kept
    word type 1 (the ones its nearest match can pick; a later page is nearer only to a later word type 1)."""
    if pages.empty:
        return np.zeros(0, bool)
    dec = decode_pages(subframe_words(pages, 8)[0].astype(np.uint64))
    valid = dec["valid"].to_numpy(bool)
    wt = dec["word_type"].to_numpy(np.int64)
    sv = pages["svId"].to_numpy(np.int64)
    iod = np.select([wt == 1, wt == 2, wt == 3, wt == 4], [dec["IODnav"], dec["IODnav2"], dec["IODnav3"], dec["IODnav4"]], -1)
    keep = last_of_each(valid & (wt >= 1) & (wt <= 4), sv, wt, iod)
    five = np.flatnonzero(valid & (wt == 5))
    keep[five[last_of_each(np.ones(five.size, bool), sv[five])]] = True
    if five.size:
        order = _order(pages)
        place = sv * (1 << 40) + order  # (satellite, place in the log), sorted as the rows are within a satellite
        fives = place[five]
        by = np.argsort(fives, kind="stable")
        ones = np.flatnonzero(keep & (wt == 1))
        at = np.searchsorted(fives[by], place[ones])
        for side in (at - 1, at):  # the nearest before, and after
            inside = (side >= 0) & (side < five.size)
            pick = five[by[side[inside]]]
            keep[pick[sv[pick] == sv[ones[inside]]]] = True
    return keep


def _nearest_week(tow_s: np.ndarray, t_now_s: np.ndarray) -> np.ndarray:
    """A time of week → the GPS seconds nearest ``t_now_s`` (the week before, of or after it)."""
    week = np.floor(t_now_s / WEEK_S)
    t = week * WEEK_S + tow_s
    return np.where(t - t_now_s > WEEK_S / 2, t - WEEK_S, np.where(t_now_s - t > WEEK_S / 2, t + WEEK_S, t))


def encode_pages(eph: dict, t_s: float) -> np.ndarray:
    """Word types 1–5 of an ephemeris (RINEX names; ``sv``, ``iode``, ``health``, ``toc_s``, ``Toe``) transmitted at
    GPS seconds ``t_s``, as a (5, 8) array of u-blox 32-bit words: nominal E1-B page pairs with their CRC-24Q.
    Values are rounded to the field's resolution."""
    words = np.zeros((5, 128), dtype=np.uint8)
    value = {field: eph[rinex] for rinex, field in RINEX_NAMES.items()}
    health = int(eph.get("health", 0))
    iod = int(eph["iode"])
    value.update(IODnav=iod, IODnav2=iod, IODnav3=iod, IODnav4=iod, SVID=int(str(eph["sv"])[1:]),
                 toe=eph["Toe"], toc=eph["toc_s"] % WEEK_S, SISA=107, WN=(int(t_s // WEEK_S) - GST_WEEK_OFFSET) % 4096,
                 TOW=int(t_s % WEEK_S), E1b_DVS=health & 1, E1b_HS=(health >> 1) & 3, E5b_DVS=(health >> 6) & 1,
                 E5b_HS=(health >> 7) & 3)  # fmt: skip
    for name, wt, start, n, _, scale, semi in FIELDS:
        if wt == 0:
            continue
        raw = int(round(float(value.get(name, 0)) / (scale * (PI_GPS if semi else 1.0)))) & ((1 << n) - 1)
        words[wt - 1, start : start + n] = [(raw >> (n - 1 - k)) & 1 for k in range(n)]
    for wt in range(1, 6):
        words[wt - 1, 0:6] = [(wt >> (5 - k)) & 1 for k in range(6)]
    bits = np.zeros((5, 256), dtype=np.uint8)
    bits[:, 2:114] = words[:, :112]  # even part: even/odd 0, page type 0, data 1; tail zeros
    bits[:, 128] = 1  # odd part
    bits[:, 130:146] = words[:, 112:]
    crc = crc24q(_crc_input(bits))
    bits[:, 128 + 82 : 128 + 106] = ((crc[:, None] >> np.arange(23, -1, -1)) & 1).astype(np.uint8)
    return (bits.reshape(5, 8, 32).astype(np.uint64) @ (np.uint64(1) << np.arange(31, -1, -1, dtype=np.uint64))).astype(np.uint32)
