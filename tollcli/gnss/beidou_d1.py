"""BeiDou D1 navigation subframes 1–3 (BDS-SIS-ICD-B1I 3.0 §5.2) → broadcast ephemerides, vectorized.

D1 is the message of the medium- and inclined-orbit satellites (C06–C58) on B1I and B3I. A u-blox ``RXM-SFRBX``
from BeiDou (``gnssId`` 3) holds one subframe as ten 32-bit words, each word's 30 bits in its low bits (the first
word's 26 data bits and 4 parity bits, the others' 22 data bits then 8 parity bits, de-interleaved); the ten are
read as one 300-bit row and every field at its place in that row (the places RTKLIB's ``decode_bds_d1`` reads,
fields split across words joined). Subframes 1, 2 and 3 whose seconds of week follow each other by 6 s make an
ephemeris, kept when its clock time equals its ephemeris time (a check the ICD's data always pass).

Times: BeiDou time (BDT) counts weeks from 2006-01-01 and runs 14 s behind GPS time: GPS seconds =
(BDT week + 1356) × 604 800 + BDT seconds + 14. The table has the RINEX field names and units of
:mod:`tollcli.gnss.orbits` (radians, seconds, metres); its clock is that of the B3I signal, to which the broadcast
clock refers (``group_delay_s`` 0; ``TGD1`` and ``TGD2`` are B1I's and B2I's delays against it, which
:func:`tollcli.gnss.raw_positions.with_broadcast_satellites` subtracts for those signals).
The geostationary satellites' D2 message (C01–C05, C59–C63) is not decoded: their measurements have no orbit.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.lnav_subframes import PI_GPS, read_bits
from tollcli.gnss.orbits import WEEK_S
from tollcli.readers.ubx import last_of_each, subframe_words

#: BDT week 0 is GPS week 1356 (2006-01-01); BDT = GPST − 14 s
BDT_WEEK_OFFSET = 1356
BDT_GPS_S = 14.0
#: (name, subframe, [(first bit, bits), …] joined most significant first, signed, scale, semicircles)
FIELDS = (
    ("frn1", 1, [(15, 3)], False, 1.0, False), ("sow1", 1, [(18, 8), (30, 12)], False, 1.0, False),
    ("SatH1", 1, [(42, 1)], False, 1.0, False), ("AODC", 1, [(43, 5)], False, 1.0, False),
    ("WN", 1, [(60, 13)], False, 1.0, False), ("toc", 1, [(73, 9), (90, 8)], False, 8.0, False),
    ("TGD1", 1, [(98, 10)], True, 0.1e-9, False), ("TGD2", 1, [(108, 4), (120, 6)], True, 0.1e-9, False),
    ("a2", 1, [(214, 11)], True, 2.0**-66, False), ("a0", 1, [(225, 7), (240, 17)], True, 2.0**-33, False),
    ("a1", 1, [(257, 5), (270, 17)], True, 2.0**-50, False), ("AODE", 1, [(287, 5)], False, 1.0, False),
    ("frn2", 2, [(15, 3)], False, 1.0, False), ("sow2", 2, [(18, 8), (30, 12)], False, 1.0, False),
    ("deltan", 2, [(42, 10), (60, 6)], True, 2.0**-43, True), ("Cuc", 2, [(66, 16), (90, 2)], True, 2.0**-31, False),
    ("M0", 2, [(92, 20), (120, 12)], True, 2.0**-31, True), ("e", 2, [(132, 10), (150, 22)], False, 2.0**-33, False),
    ("Cus", 2, [(180, 18)], True, 2.0**-31, False), ("Crc", 2, [(198, 4), (210, 14)], True, 2.0**-6, False),
    ("Crs", 2, [(224, 8), (240, 10)], True, 2.0**-6, False), ("sqrtA", 2, [(250, 12), (270, 20)], False, 2.0**-19, False),
    ("toe_msb", 2, [(290, 2)], False, 1.0, False),
    ("frn3", 3, [(15, 3)], False, 1.0, False), ("sow3", 3, [(18, 8), (30, 12)], False, 1.0, False),
    ("toe_lsb", 3, [(42, 10), (60, 5)], False, 1.0, False), ("i0", 3, [(65, 17), (90, 15)], True, 2.0**-31, True),
    ("Cic", 3, [(105, 7), (120, 11)], True, 2.0**-31, False), ("Omegad", 3, [(131, 11), (150, 13)], True, 2.0**-43, True),
    ("Cis", 3, [(163, 9), (180, 9)], True, 2.0**-31, False), ("IDOT", 3, [(189, 13), (210, 1)], True, 2.0**-43, True),
    ("Omega0", 3, [(211, 21), (240, 11)], True, 2.0**-31, True), ("omega", 3, [(251, 11), (270, 21)], True, 2.0**-31, True),
)  # fmt: skip
RINEX_NAMES = {"SVclockBias": "a0", "SVclockDrift": "a1", "SVclockDriftRate": "a2", "Crs": "Crs", "DeltaN": "deltan",
               "M0": "M0", "Cuc": "Cuc", "Eccentricity": "e", "Cus": "Cus", "sqrtA": "sqrtA", "Cic": "Cic",
               "Omega0": "Omega0", "Cis": "Cis", "Io": "i0", "Crc": "Crc", "omega": "omega", "OmegaDot": "Omegad",
               "IDOT": "IDOT"}  # fmt: skip


def is_geostationary(prn: np.ndarray) -> np.ndarray:
    """BeiDou satellite numbers of the geostationary satellites (D2 message; their own orbit rotation)."""
    prn = np.asarray(prn)
    return (prn <= 5) | (prn >= 59)


def subframe_bits(words: np.ndarray) -> np.ndarray:
    """(n, 10) SFRBX words → (n, 300) bits: each word's low 30 bits, most significant first."""
    w = np.asarray(words, dtype=np.uint64).reshape(-1, 10) & np.uint64(0x3FFFFFFF)
    shifts = np.arange(29, -1, -1, dtype=np.uint64)
    return ((w[..., None] >> shifts) & np.uint64(1)).astype(np.uint8).reshape(-1, 300)


def _joined(bits: np.ndarray, parts, signed: bool) -> np.ndarray:
    value = np.zeros(len(bits), np.int64)
    total = 0
    for start, n in parts:
        value = (value << n) | read_bits(bits, start, n, False)
        total += n
    if signed:
        value = np.where(value >= (1 << (total - 1)), value - (1 << total), value)
    return value


def decode_subframes(words: np.ndarray) -> pd.DataFrame:
    """Per subframe: its number (``frn``), its seconds of week (``sow``) and the fields of subframes 1–3 read as if
    it were each (only the one it is counts), scaled."""
    bits = subframe_bits(words)
    out = {"frn": _joined(bits, [(15, 3)], False), "sow": _joined(bits, [(18, 8), (30, 12)], False)}
    for name, _sub, parts, signed, scale, semicircles in FIELDS:
        raw = _joined(bits, parts, signed)
        out[name] = raw * scale * (PI_GPS if semicircles else 1.0) if (scale != 1.0 or semicircles) else raw
    return pd.DataFrame(out)


def ephemerides(subframes: pd.DataFrame) -> pd.DataFrame:
    """Ephemerides of the D1 satellites from their subframes 1–3 (``subframes``: ``svId`` and ``words`` per SFRBX).
    Subframes 1, 2 and 3 join when their seconds of week are t, t + 6 and t + 12; a geostationary satellite's, or
    one whose clock time differs from its ephemeris time, is left out."""
    columns = ["sv", "toc_s", "toe_s", "group_delay_s", "health", *RINEX_NAMES, "TGD1", "TGD2"]
    joined, t_gps = _triples(subframes)
    if joined.empty:
        return pd.DataFrame(columns=columns)
    source = {"a0": "a0_1", "a1": "a1_1", "a2": "a2_1", "deltan": "deltan_2", "M0": "M0_2", "Cuc": "Cuc_2", "e": "e_2",
              "Cus": "Cus_2", "Crc": "Crc_2", "Crs": "Crs_2", "sqrtA": "sqrtA_2", "i0": "i0_3", "Cic": "Cic_3",
              "Omegad": "Omegad_3", "Cis": "Cis_3", "IDOT": "IDOT_3", "Omega0": "Omega0_3", "omega": "omega_3"}  # fmt: skip
    out = pd.DataFrame({"sv": ["C%02d" % s for s in joined["svId"]], "toc_s": t_gps, "toe_s": t_gps,
                        "group_delay_s": 0.0, "health": joined["SatH1_1"].to_numpy(float)})  # fmt: skip
    for rinex, field in RINEX_NAMES.items():
        out[rinex] = joined[source[field]].to_numpy(float)
    out["TGD1"] = joined["TGD1_1"].to_numpy(float)
    out["TGD2"] = joined["TGD2_1"].to_numpy(float)
    return out.drop_duplicates(["sv", "toc_s"], keep="last").sort_values(["sv", "toc_s"], kind="stable").reset_index(drop=True)


def _decoded(subframes: pd.DataFrame) -> pd.DataFrame:
    """Every subframe decoded (a shorter one's words are not: zeros), with ``svId``, its ``row`` in ``subframes`` and
    ``ok``: a whole subframe 1–3 of a satellite that is not geostationary."""
    prn = subframes["svId"].to_numpy(np.int64)
    words, count = subframe_words(subframes, 10)
    whole = count >= 10
    d = decode_subframes(np.where(whole[:, None], words, np.uint32(0)))
    d["svId"] = prn
    d["row"] = np.arange(len(d))
    d["ok"] = ~is_geostationary(prn) & whole & d["frn"].between(1, 3).to_numpy()
    return d


def _triples(subframes: pd.DataFrame, decoded: pd.DataFrame | None = None) -> tuple[pd.DataFrame, np.ndarray]:
    """The joined subframes 1, 2, 3 of each (satellite, seconds of week) whose clock time is their ephemeris time (the
    last of each subframe where one came twice), in the order of their subframes 1, with each part's ``row_1`` …
    ``row_3``; and their ephemeris time (GPS seconds). ``decoded``: :func:`_decoded` of ``subframes`` when made."""
    if subframes.empty:
        return pd.DataFrame(), np.zeros(0)
    d = _decoded(subframes) if decoded is None else decoded
    d = d[d["ok"].to_numpy()]
    one = d[d["frn"] == 1].drop_duplicates(["svId", "sow"], keep="last")
    two = d[d["frn"] == 2].assign(sow=lambda x: x["sow"] - 6).drop_duplicates(["svId", "sow"], keep="last")
    three = d[d["frn"] == 3].assign(sow=lambda x: x["sow"] - 12).drop_duplicates(["svId", "sow"], keep="last")
    joined = one.set_index(["svId", "sow"]).add_suffix("_1").join(two.set_index(["svId", "sow"]).add_suffix("_2"), how="inner")
    joined = joined.join(three.set_index(["svId", "sow"]).add_suffix("_3"), how="inner").reset_index()
    toe = (joined["toe_msb_2"].to_numpy(np.int64) * 2**15 + joined["toe_lsb_3"].to_numpy(np.int64)) * 8.0
    toc = joined["toc_1"].to_numpy(float)
    joined = joined[toe == toc]
    toe = toe[toe == toc]
    if joined.empty:
        return joined, np.zeros(0)
    sow = joined["sow"].to_numpy(float)
    week = joined["WN_1"].to_numpy(float)
    week = np.where(toe > sow + WEEK_S / 2, week + 1, np.where(toe < sow - WEEK_S / 2, week - 1, week))  # ephemeris across a week's turn
    return joined, (week + BDT_WEEK_OFFSET) * WEEK_S + toe + BDT_GPS_S


#: how far back (s of BeiDou time) a subframe can still arrive after its satellite's latest one (a second signal's
#: copy of the same subframe comes within seconds): :func:`kept` keeps the subframes of that span
LATE_S = 120.0


def kept(subframes: pd.DataFrame) -> np.ndarray:
    """(n,) the subframes of ``subframes`` (as :func:`ephemerides` takes them, in log order) that can still change its
    result as more follow: of the whole subframes 1–3 of satellites not geostationary, the last of each (satellite,
    subframe, seconds of week) that is part of the latest triple of its ephemeris time (the one :func:`ephemerides`
    keeps) or within :data:`LATE_S` of its satellite's latest subframe (a triple still to be completed, or a copy
    from another signal still to come). A subframe arriving more than :data:`LATE_S` after its satellite's later ones
    (a log out of order) could have joined a triple whose other parts are no longer kept."""
    if subframes.empty:
        return np.zeros(0, bool)
    d = _decoded(subframes)
    ok = d["ok"].to_numpy(bool)
    prn, sow = d["svId"].to_numpy(np.int64), d["sow"].to_numpy(np.int64)
    last = last_of_each(ok, prn, d["frn"].to_numpy(np.int64), sow)
    latest = pd.Series(sow[ok]).groupby(prn[ok]).last()  # each satellite's latest subframe's seconds of week
    behind = (latest.reindex(prn).to_numpy(float) - sow) % WEEK_S  # (across a week's turn too)
    keep = last & (behind <= LATE_S)
    joined, t_gps = _triples(subframes, d)
    if len(joined):
        winners = joined.assign(t=t_gps).drop_duplicates(["svId", "t"], keep="last")
        for part in ("row_1", "row_2", "row_3"):
            keep[winners[part].to_numpy(np.int64)] = True
    return keep
