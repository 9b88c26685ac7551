"""GPS LNAV subframes 1–3 (IS-GPS-200 §20.3.3) ↔ broadcast ephemerides, vectorized over subframes.

A subframe is ten 30-bit words as a u-blox ``RXM-SFRBX`` delivers them (one per 32-bit ``dwrd``, data
bits 29…6 already in true polarity, parity in 5…0). The 24 data bits of each word are packed into a
240-bit row and every field is read at its IS-GPS-200 position in that row, all subframes at once.

:func:`decode_subframes` gives the raw integer fields (as gpsd's ``EPHEM1``/``EPHEM2``/``EPHEM3``
unscaled reports name them); :func:`ephemerides` joins subframes 1, 2, 3 of one issue (IODC's low
byte = IODE of 2 = IODE of 3) into ephemerides with the RINEX field names and units of
:mod:`tollcli.gnss.orbits` (radians, seconds, metres). :func:`encode_subframes` is the inverse (an
ephemeris → the three subframes' words, parity included), for round trips and simulated receivers.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.orbits import WEEK_S
from tollcli.readers.ubx import last_of_each, subframe_words

PI_GPS = 3.1415926535898  # IS-GPS-200's π for semicircles
PREAMBLE = 0x8B
#: (name, subframe, first bit in the 240-bit row, bits, signed, scale, semicircles) — IS-GPS-200 Table 20-I/III
FIELDS = (
    ("WN", 1, 48, 10, False, 1.0, False), ("L2", 1, 58, 2, False, 1.0, False), ("ura", 1, 60, 4, False, 1.0, False),
    ("hlth", 1, 64, 6, False, 1.0, False), ("IODC_msb", 1, 70, 2, False, 1.0, False), ("L2P", 1, 72, 1, False, 1.0, False),
    ("Tgd", 1, 160, 8, True, 2.0**-31, False), ("IODC_lsb", 1, 168, 8, False, 1.0, False),
    ("toc", 1, 176, 16, False, 16.0, False), ("af2", 1, 192, 8, True, 2.0**-55, False),
    ("af1", 1, 200, 16, True, 2.0**-43, False), ("af0", 1, 216, 22, True, 2.0**-31, False),
    ("IODE", 2, 48, 8, False, 1.0, False), ("Crs", 2, 56, 16, True, 2.0**-5, False),
    ("deltan", 2, 72, 16, True, 2.0**-43, True), ("M0", 2, 88, 32, True, 2.0**-31, True),
    ("Cuc", 2, 120, 16, True, 2.0**-29, False), ("e", 2, 136, 32, False, 2.0**-33, False),
    ("Cus", 2, 168, 16, True, 2.0**-29, False), ("sqrtA", 2, 184, 32, False, 2.0**-19, False),
    ("toe", 2, 216, 16, False, 16.0, False), ("FIT", 2, 232, 1, False, 1.0, False), ("AODO", 2, 233, 5, False, 1.0, False),
    ("Cic", 3, 48, 16, True, 2.0**-29, False), ("Omega0", 3, 64, 32, True, 2.0**-31, True),
    ("Cis", 3, 96, 16, True, 2.0**-29, False), ("i0", 3, 112, 32, True, 2.0**-31, True),
    ("Crc", 3, 144, 16, True, 2.0**-5, False), ("omega", 3, 160, 32, True, 2.0**-31, True),
    ("Omegad", 3, 192, 24, True, 2.0**-43, True), ("IODE3", 3, 216, 8, False, 1.0, False),
    ("IDOT", 3, 224, 14, True, 2.0**-43, True),
)  # fmt: skip
#: ephemeris field (RINEX name) ← LNAV field
RINEX_NAMES = {"SVclockBias": "af0", "SVclockDrift": "af1", "SVclockDriftRate": "af2", "Crs": "Crs", "DeltaN": "deltan",
               "M0": "M0", "Cuc": "Cuc", "Eccentricity": "e", "Cus": "Cus", "sqrtA": "sqrtA", "Cic": "Cic",
               "Omega0": "Omega0", "Cis": "Cis", "Io": "i0", "Crc": "Crc", "omega": "omega", "OmegaDot": "Omegad",
               "IDOT": "IDOT", "TGD": "Tgd"}  # fmt: skip


def subframe_bits(words: np.ndarray) -> np.ndarray:
    """(n, 10) 32-bit words → (n, 240) data bits (each word's bits 29…6, most significant first)."""
    data = (np.asarray(words, dtype=np.uint64) >> np.uint64(6)) & np.uint64(0xFFFFFF)
    shifts = np.arange(23, -1, -1, dtype=np.uint64)
    return ((data[..., None] >> shifts) & np.uint64(1)).astype(np.uint8).reshape(len(data), 240)


def read_bits(bits: np.ndarray, start: int, n: int, signed: bool) -> np.ndarray:
    """An ``n``-bit field from bit ``start`` of each row, as int64 (two's complement when ``signed``)."""
    value = bits[:, start : start + n].astype(np.int64) @ (np.int64(1) << np.arange(n - 1, -1, -1, dtype=np.int64))
    if signed:
        value = np.where(value >= (1 << (n - 1)), value - (1 << n), value)
    return value


def decode_subframes(words: np.ndarray) -> pd.DataFrame:
    """Per subframe: ``preamble_ok``, ``subframe`` (1–5), ``tow_s`` (HOW: start of the next subframe) and the raw
    integer fields of its kind (gpsd's unscaled names; fields of other subframes are −1)."""
    bits = subframe_bits(words)
    sfid = read_bits(bits, 43, 3, False)
    out = {"preamble_ok": read_bits(bits, 0, 8, False) == PREAMBLE, "subframe": sfid,
           "tow_s": read_bits(bits, 24, 17, False) * 6}  # fmt: skip
    for name, sub, start, n, signed, _, _ in FIELDS:
        out[name] = np.where(sfid == sub, read_bits(bits, start, n, signed), -1 if not signed else 0)
    return pd.DataFrame(out)


def ephemerides(sfrbx: pd.DataFrame, gps_week_hint: float) -> pd.DataFrame:
    """GPS ephemerides from decoded subframes (``sv`` and ``words`` columns), one per (satellite, issue).

    ``gps_week_hint``: a full GPS week near the data (the receiver's), to undo the 10-bit week number.
    Columns: the RINEX names of :data:`tollcli.gnss.orbits.EPHEMERIS_FIELDS`, ``sv``, ``toc_s``, ``toe_s``,
    ``group_delay_s``, ``health``, ``iode``.
    """
    columns = ["sv", "toc_s", "toe_s", "group_delay_s", "health", "iode", *RINEX_NAMES, "Toe"]
    if sfrbx.empty:
        return pd.DataFrame(columns=columns)
    dec = decode_subframes(subframe_words(sfrbx, 10)[0])
    dec["sv"] = sfrbx["sv"].to_numpy(str)
    dec = dec[dec["preamble_ok"]]
    one = dec[dec["subframe"] == 1].assign(iode=lambda t: t["IODC_lsb"])
    two = dec[dec["subframe"] == 2].assign(iode=lambda t: t["IODE"])
    three = dec[dec["subframe"] == 3].assign(iode=lambda t: t["IODE3"])
    keep = {1: ["WN", "hlth", "Tgd", "toc", "af2", "af1", "af0"],
            2: ["Crs", "deltan", "M0", "Cuc", "e", "Cus", "sqrtA", "toe"],
            3: ["Cic", "Omega0", "Cis", "i0", "Crc", "omega", "Omegad", "IDOT"]}  # fmt: skip
    joined = (one[["sv", "iode", *keep[1]]].drop_duplicates(["sv", "iode"], keep="last")
              .merge(two[["sv", "iode", *keep[2]]].drop_duplicates(["sv", "iode"], keep="last"), on=["sv", "iode"])
              .merge(three[["sv", "iode", *keep[3]]].drop_duplicates(["sv", "iode"], keep="last"), on=["sv", "iode"]))  # fmt: skip
    if joined.empty:
        return pd.DataFrame(columns=columns)
    scale = {name: (s * (PI_GPS if semi else 1.0)) for name, _, _, _, _, s, semi in FIELDS}
    eph = pd.DataFrame({"sv": joined["sv"].to_numpy(str), "iode": joined["iode"].to_numpy(np.int64)})
    for rinex, lnav in RINEX_NAMES.items():
        eph[rinex] = joined[lnav].to_numpy(np.int64) * scale[lnav]
    week = full_week(joined["WN"].to_numpy(np.int64), gps_week_hint)
    eph["Toe"] = joined["toe"].to_numpy(np.int64) * 16.0
    eph["toe_s"] = week * WEEK_S + eph["Toe"]
    eph["toc_s"] = week * WEEK_S + joined["toc"].to_numpy(np.int64) * 16.0
    eph["group_delay_s"] = eph["TGD"]
    eph["health"] = joined["hlth"].to_numpy(np.int64)
    return eph[columns]


def kept(sfrbx: pd.DataFrame) -> np.ndarray:
    """(n,) the subframes of ``sfrbx`` (as :func:`ephemerides` takes them, in log order) that can still change its
    result, whatever subframes follow: of those with a good preamble, the last of each satellite, subframe 1–3 and
    issue. :func:`ephemerides` reads only those (it keeps the last of each), so its result from the kept rows and any
    that follow is its result from all of them."""
    if sfrbx.empty:
        return np.zeros(0, bool)
    dec = decode_subframes(subframe_words(sfrbx, 10)[0])
    sub = dec["subframe"].to_numpy(np.int64)
    iode = np.select([sub == 1, sub == 2, sub == 3], [dec["IODC_lsb"], dec["IODE"], dec["IODE3"]], -1)
    ok = dec["preamble_ok"].to_numpy(bool) & (sub >= 1) & (sub <= 3)
    return last_of_each(ok, sfrbx["svId"].to_numpy(np.int64), sub, iode)


def full_week(wn10: np.ndarray, hint_week: float) -> np.ndarray:
    """A 10-bit week number → the full GPS week nearest ``hint_week``."""
    return wn10 + 1024 * np.round((hint_week - wn10) / 1024.0)


def encode_subframes(eph: dict, week: int, tow_s: int) -> np.ndarray:
    """Subframes 1, 2, 3 of an ephemeris (RINEX names; ``iode``, ``health``, ``toc_s``/``Toe`` of week) as a (3, 10)
    array of u-blox 32-bit words with IS-GPS-200 parity. Values are rounded to the field's resolution."""
    rows = np.zeros((3, 240), dtype=np.uint8)
    lnav_value = {lnav: eph[rinex] for rinex, lnav in RINEX_NAMES.items()}
    lnav_value.update(WN=week % 1024, hlth=eph.get("health", 0), toc=(eph["toc_s"] % WEEK_S), toe=eph["Toe"],
                      IODE=eph["iode"], IODE3=eph["iode"], IODC_lsb=eph["iode"], IODC_msb=0, L2=1, ura=0, L2P=0,
                      FIT=0, AODO=0)  # fmt: skip
    for name, sub, start, n, signed, scale, semi in FIELDS:
        raw = int(round(float(lnav_value.get(name, 0)) / (scale * (PI_GPS if semi else 1.0))))
        raw &= (1 << n) - 1
        rows[sub - 1, start : start + n] = [(raw >> (n - 1 - k)) & 1 for k in range(n)]
    for sub in range(3):
        _put(rows[sub], 0, 8, PREAMBLE)
        _put(rows[sub], 24, 17, ((tow_s + 6 * (sub + 1)) // 6) % 100800)
        _put(rows[sub], 43, 3, sub + 1)
    data = rows.reshape(3, 10, 24).astype(np.int64) @ (np.int64(1) << np.arange(23, -1, -1, dtype=np.int64))
    return np.array([[_with_parity(int(d), prev) for d, prev in zip(row, [0, *row[:-1]])] for row in data], dtype=np.uint32)


def _put(row: np.ndarray, start: int, n: int, value: int) -> None:
    row[start : start + n] = [(value >> (n - 1 - k)) & 1 for k in range(n)]


def _with_parity(data24: int, prev_data24: int) -> int:
    """A 30-bit word (data in true polarity, D29*/D30* of the previous word taken as 0) with its parity bits."""
    d = [(data24 >> (23 - k)) & 1 for k in range(24)]  # d[0] = D1
    taps = ((1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23), (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24),
            (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22), (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23),
            (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24), (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24))  # fmt: skip
    parity = 0
    for t in taps:
        parity = (parity << 1) | (sum(d[i - 1] for i in t) & 1)
    return (data24 << 6) | parity
