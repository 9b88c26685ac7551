"""GLONASS navigation strings (GLONASS ICD 5.1 §4.4) → broadcast ephemerides, vectorized over strings.

A u-blox ``RXM-SFRBX`` from GLONASS (``gnssId`` 6) holds one string of the navigation frame in four 32-bit words:
the string's 85 bits (idle bit, 76 data bits, 8 Hamming check bits) from the most significant bit of the first word,
and in the fourth word the superframe and frame numbers (its upper 16 bits name the frame). A string counts when
every check of its Hamming code (ICD §4.7, the masks of RTKLIB's ``test_glostr``) holds: one that a single wrong bit
would explain is left out too, not corrected (RTKLIB keeps it, uncorrected; a charge must not rest on a guessed
bit). Strings 1–4 of one frame are the immediate
data: position, velocity and lunisolar acceleration along x (string 1), y (2), z (3), the reference time t_b (2), γ_n
(3), τ_n and the slot number n (4); all sign-and-magnitude.

Times: t_b counts 15-minute steps of the day in Moscow time (UTC + 3 h). The day is that of the string's receive
time (the nearest t_b within ±12 h of it), turned into GPS time with the leap seconds of that date. The ephemeris
table has the columns :mod:`tollcli.gnss.glonass_orbits` reads, in metres and seconds, ``sv`` (``R`` + slot),
``toe_s`` = ``toc_s`` = t_b, ``health`` (B_n's most significant bit: unhealthy), ``FreqNum`` left unknown (the
receiver's frequency slot comes with its measurements).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.lnav_subframes import read_bits
from tollcli.readers.ubx import last_of_each, subframe_words

#: the 8 Hamming check masks over the string's first 11 bytes (ICD §4.7, as RTKLIB's test_glostr)
_HAMMING = np.array([
    [0x55, 0x55, 0x5A, 0xAA, 0xAA, 0xAA, 0xB5, 0x55, 0x6A, 0xD8, 0x08],
    [0x66, 0x66, 0x6C, 0xCC, 0xCC, 0xCC, 0xD9, 0x99, 0xB3, 0x68, 0x10],
    [0x87, 0x87, 0x8F, 0x0F, 0x0F, 0x0F, 0x1E, 0x1E, 0x3C, 0x70, 0x20],
    [0x07, 0xF8, 0x0F, 0xF0, 0x0F, 0xF0, 0x1F, 0xE0, 0x3F, 0x80, 0x40],
    [0xF8, 0x00, 0x0F, 0xFF, 0xF0, 0x00, 0x1F, 0xFF, 0xC0, 0x00, 0x80],
    [0x00, 0x00, 0x0F, 0xFF, 0xFF, 0xFF, 0xE0, 0x00, 0x00, 0x01, 0x00],
    [0xFF, 0xFF, 0xF0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00],
    [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xF8],
], dtype=np.uint8)  # fmt: skip
#: (name, string, first bit in the string, bits, sign-magnitude, scale) — ICD Table 4.5; bit 0 is the idle bit
FIELDS = (
    ("m1", 1, 1, 4, False, 1.0), ("tk_h", 1, 9, 5, False, 1.0), ("tk_m", 1, 14, 6, False, 1.0),
    ("dX", 1, 21, 24, True, 2.0**-20 * 1e3), ("dX2", 1, 45, 5, True, 2.0**-30 * 1e3), ("X", 1, 50, 27, True, 2.0**-11 * 1e3),
    ("m2", 2, 1, 4, False, 1.0), ("Bn", 2, 5, 3, False, 1.0), ("tb", 2, 9, 7, False, 1.0),
    ("dY", 2, 21, 24, True, 2.0**-20 * 1e3), ("dY2", 2, 45, 5, True, 2.0**-30 * 1e3), ("Y", 2, 50, 27, True, 2.0**-11 * 1e3),
    ("m3", 3, 1, 4, False, 1.0), ("gamma_n", 3, 6, 11, True, 2.0**-40),
    ("dZ", 3, 21, 24, True, 2.0**-20 * 1e3), ("dZ2", 3, 45, 5, True, 2.0**-30 * 1e3), ("Z", 3, 50, 27, True, 2.0**-11 * 1e3),
    ("m4", 4, 1, 4, False, 1.0), ("tau_n", 4, 5, 22, True, 2.0**-30), ("En", 4, 32, 5, False, 1.0),
    ("NT", 4, 59, 11, False, 1.0), ("slot", 4, 70, 5, False, 1.0),
)  # fmt: skip
MOSCOW_S = 10_800.0
DAY_S = 86_400.0


def string_bytes(words: np.ndarray) -> np.ndarray:
    """(n, 4) SFRBX words → (n, 16) bytes, each word most significant byte first."""
    w = np.asarray(words, dtype=np.uint32).reshape(-1, 4)
    return w.astype(">u4").view(np.uint8).reshape(-1, 16)


def hamming_ok(data: np.ndarray) -> np.ndarray:
    """Whether each string (n, ≥ 11 bytes) passes every check of the ICD's Hamming code."""
    masked = data[:, None, :11] & _HAMMING[None, :, :]
    checks = np.unpackbits(masked, axis=2).sum(axis=2) % 2  # (n, 8) parity of each masked sum
    return checks.sum(axis=1) == 0


def _field(bits: np.ndarray, start: int, n: int, sign_magnitude: bool) -> np.ndarray:
    if sign_magnitude:  # the first bit is the sign, the rest the magnitude
        value = read_bits(bits, start + 1, n - 1, False)
        return np.where(bits[:, start] == 1, -value, value)
    return read_bits(bits, start, n, False)


def decode_strings(words: np.ndarray) -> pd.DataFrame:
    """Per string: ``ok`` (Hamming), the string number ``m``, the frame key (superframe and frame numbers) and every
    field of strings 1–4 read as if the string were that one (only the one it is counts)."""
    data = string_bytes(words)
    bits = np.unpackbits(data[:, :11], axis=1)
    out = {"ok": hamming_ok(data), "m": _field(bits, 1, 4, False), "frame": (np.asarray(words, np.uint64).reshape(-1, 4)[:, 3] >> np.uint64(16)).astype(np.int64)}
    for name, _string, start, n, sm, scale in FIELDS:
        raw = _field(bits, start, n, sm)
        out[name] = raw * scale if scale != 1.0 else raw
    return pd.DataFrame(out)


def kept(strings: pd.DataFrame) -> np.ndarray:
    """(n,) the strings of ``strings`` (as :func:`ephemerides` takes them, in log order) that can still change its
    result, whatever strings follow: of those passing their Hamming check, the last string 1–4 of each satellite and
    frame (the ones :func:`ephemerides` joins: it keeps the last of each; their receive times, read from their
    ``message`` numbers afterwards, are what they would be). As many are kept as the receiver's frame numbers take
    values (the recordings here have no GLONASS navigation data to measure it on)."""
    if strings.empty:
        return np.zeros(0, bool)
    d = decode_strings(subframe_words(strings, 4)[0])
    ok = d["ok"].to_numpy(bool) & d["m"].between(1, 4).to_numpy()
    return last_of_each(ok, strings["svId"].to_numpy(np.int64), d["frame"].to_numpy(np.int64), d["m"].to_numpy(np.int64))


def ephemerides(strings: pd.DataFrame, receive_gps_s: np.ndarray, leap_s) -> pd.DataFrame:
    """Ephemerides from strings 1–4 of one frame of one satellite (``strings``: ``svId`` and ``words`` per SFRBX;
    ``receive_gps_s``: each string's receive time, GPS seconds; ``leap_s``: GPS − UTC seconds at a GPS time, a
    function). Strings failing their Hamming check are left out; so is a frame whose slot number contradicts
    the receiver's satellite number."""
    columns = ["sv", "toc_s", "toe_s", "health", "X", "Y", "Z", "dX", "dY", "dZ", "dX2", "dY2", "dZ2", "SVclockBias",
               "SVrelFreqBias", "FreqNum"]  # fmt: skip
    if strings.empty:
        return pd.DataFrame(columns=columns)
    d = decode_strings(subframe_words(strings, 4)[0])
    d["svId"] = strings["svId"].to_numpy(np.int64)
    d["t_rx"] = np.asarray(receive_gps_s, float)
    d = d[d["ok"] & d["m"].between(1, 4) & np.isfinite(d["t_rx"])]
    parts = []
    keys = ["svId", "frame"]
    for m in (1, 2, 3, 4):
        part = d[d["m"] == m].drop_duplicates(keys, keep="last").set_index(keys)
        parts.append(part.add_suffix(f"_{m}"))
    joined = parts[0].join(parts[1:], how="inner").reset_index()
    joined = joined[(joined["slot_4"] == joined["svId"]) & (joined["slot_4"] >= 1)]
    if joined.empty:
        return pd.DataFrame(columns=columns)
    t_rx = joined["t_rx_2"].to_numpy(float)
    leap = np.asarray(leap_s(t_rx), float)
    utc = t_rx - leap
    day_start = np.floor(utc / DAY_S) * DAY_S
    toe_utc = day_start + joined["tb_2"].to_numpy(float) * 900.0 - MOSCOW_S
    toe_utc = np.where(toe_utc < utc - DAY_S / 2, toe_utc + DAY_S, np.where(toe_utc > utc + DAY_S / 2, toe_utc - DAY_S, toe_utc))
    toe = toe_utc + leap
    out = pd.DataFrame({
        "sv": ["R%02d" % s for s in joined["slot_4"]],
        "toc_s": toe, "toe_s": toe,
        "health": (joined["Bn_2"].to_numpy(np.int64) >> 2).astype(float),
        "X": joined["X_1"].to_numpy(float), "Y": joined["Y_2"].to_numpy(float), "Z": joined["Z_3"].to_numpy(float),
        "dX": joined["dX_1"].to_numpy(float), "dY": joined["dY_2"].to_numpy(float), "dZ": joined["dZ_3"].to_numpy(float),
        "dX2": joined["dX2_1"].to_numpy(float), "dY2": joined["dY2_2"].to_numpy(float), "dZ2": joined["dZ2_3"].to_numpy(float),
        "SVclockBias": -joined["tau_n_4"].to_numpy(float), "SVrelFreqBias": joined["gamma_n_3"].to_numpy(float),
        "FreqNum": np.nan,
    })  # fmt: skip
    return out.drop_duplicates(["sv", "toc_s"], keep="last").sort_values(["sv", "toc_s"], kind="stable").reset_index(drop=True)
