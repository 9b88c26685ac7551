"""Galileo I/NAV nominal pages → a page table for OSNMA, from the ICD test-vector CSV or a u-blox log.

A page is 240 bits: the even half (120 bits: even/odd bit, page type, 112 data bits, 6 tail bits) then
the odd half (even/odd bit, page type, 16 data bits, the 40-bit OSNMA field — 8 bits of HKROOT and 32 of
MACK —, 22 SAR bits, 2 spare, the CRC-24Q, 8 SSP bits, 6 tail bits). ``tow_s`` is the Galileo system time of
week the page is labelled with, as the ICD test vectors label it: the start of its odd half, an odd second;
a subframe (15 pages, 30 s) starts at a multiple of 30 s and its page ``k`` has ``tow_s % 30 == 2k + 1``.

* ICD test vectors (``TOW,WN,SVID,hex``, one page a line, E1-B): read as given.
* u-blox ``RXM-SFRBX`` (``gnssId`` 2; ``sigId`` 1 is E1-B, 5 is E5b-I): eight 32-bit words, the even half in
  words 0–3 and the odd half in words 4–7, each half's last 8 bits padding. The receiver outputs a page
  after the navigation epoch that follows its end; the time is the ``NAV-TIMEGAL`` of the epoch before the
  page: a page read after GST ``T`` began at ``T − 4`` (T even) or ``T − 3`` (T odd) and is labelled one
  second later. ``tests/test_osnma_pages.py`` checks the label against the time of week word types 0, 5
  and 6 carry in themselves. Pages read before the first ``NAV-TIMEGAL``, or a second page of one satellite
  and band under the same clock, have no trustworthy time and are dropped (counted).

``crc_ok`` is the CRC-24Q over the 196 bits before it (:func:`tollcli.gnss.inav_words.crc24q`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.gnss.inav_words import crc24q

E1B, E5B = "E1-B", "E5b-I"
#: the OSNMA field's place in a 240-bit page
HKROOT_BITS = slice(138, 146)
MACK_BITS = slice(146, 178)
_UBX_SIGNAL = {1: E1B, 5: E5B}
_SFRBX, _TIMEGAL = (0x02, 0x13), (0x01, 0x25)


@dataclass
class Pages:
    table: pd.DataFrame  # svid, wn, tow_s, band, bits (240-character '0'/'1' str), crc_ok, line
    n_dropped: int  # pages without a trustworthy time (u-blox) or malformed lines (CSV)
    source: str


def _crc_ok(bits: np.ndarray) -> np.ndarray:
    """(n, 240) uint8 bits → whether each page's CRC-24Q matches."""
    if not len(bits):
        return np.zeros(0, bool)
    data = np.hstack([np.zeros((len(bits), 4), np.uint8), bits[:, :114], bits[:, 120:202]])
    crc = (bits[:, 202:226].astype(np.int64) << np.arange(23, -1, -1)).sum(axis=1)
    return crc24q(data) == crc


def _bit_strings(bits: np.ndarray) -> np.ndarray:
    packed = (bits + ord("0")).astype(np.uint8)
    return np.array([row.tobytes().decode() for row in packed], dtype=object)


def _table(svid, wn, tow, band, bits: np.ndarray, line) -> pd.DataFrame:
    return pd.DataFrame({"svid": np.asarray(svid, np.int64), "wn": np.asarray(wn, np.int64), "tow_s": np.asarray(tow, np.int64),
                         "band": np.asarray(band, object), "bits": _bit_strings(bits), "crc_ok": _crc_ok(bits),
                         "line": np.asarray(line, np.int64)})  # fmt: skip


def read_icd_stream_csv(path: str | os.PathLike) -> Pages:
    """The ICD test vectors as published: ``SVID,NumNavBits,NavBitsHEX``, each satellite's whole bit stream
    (120 bit/s, pages of 240 bits back to back) from the GST the file name gives (``16_AUG_2023_GST_05_00_01``)."""
    import datetime as dt
    import re

    name = os.path.basename(str(path))
    m = re.match(r"(\d{2})_([A-Z]{3})_(\d{4})_GST_(\d{2})_(\d{2})_(\d{2})", name)
    if m is None:
        raise DataError(f"{path}: a page stream file's name must give its start (DD_MON_YYYY_GST_HH_MM_SS)")
    start = dt.datetime.strptime("_".join(m.groups()), "%d_%b_%Y_%H_%M_%S")
    seconds = int((start - dt.datetime(1999, 8, 22)).total_seconds())
    wn, tow = divmod(seconds, 604800)
    raw = pd.read_csv(path, dtype=str)
    rows, bits_rows = [], []
    for svid, n_bits, hexes in raw.itertuples(index=False):
        n = int(n_bits) // 240
        nib = np.frombuffer(hexes.strip().encode(), np.uint8)
        val = np.where(nib >= ord("a"), nib - 87, np.where(nib >= ord("A"), nib - 55, nib - 48)).astype(np.uint8)
        b = ((val[:, None] >> np.arange(3, -1, -1, dtype=np.uint8)) & 1).reshape(-1)[: n * 240].reshape(n, 240)
        bits_rows.append(b)
        rows.append(np.column_stack([np.full(n, int(svid)), tow + 2 * np.arange(n)]))
    ids = np.vstack(rows)
    bits = np.vstack(bits_rows)
    order = np.lexsort((ids[:, 0], ids[:, 1]))
    t = ids[order, 1]
    table = _table(ids[order, 0], wn + t // 604800, t % 604800, np.full(len(t), E1B), bits[order], order + 1)
    return Pages(table, 0, str(path))


def read_icd_csv(path: str | os.PathLike, strict: bool = False) -> Pages:
    """The OSNMA ICD test-vector CSV (``TOW,WN,SVID,NAVBitsHEX``; a header line is skipped), or the stream form."""
    try:
        with open(path, encoding="ascii", errors="replace") as stream:
            if stream.readline().startswith("SVID,NumNavBits"):
                return read_icd_stream_csv(path)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    try:
        raw = pd.read_csv(path, header=None, names=["tow", "wn", "svid", "hex"], dtype=str, keep_default_na=False)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    line = np.arange(1, len(raw) + 1)
    hexes = raw["hex"].str.strip()
    ok = hexes.str.fullmatch(r"[0-9A-Fa-f]{60}") & raw["tow"].str.fullmatch(r"\d+") & raw["svid"].str.fullmatch(r"\d+")
    bad = np.flatnonzero(~ok.to_numpy())
    header = bool(len(raw)) and not ok.iloc[0] and not str(raw["tow"].iloc[0]).strip().isdigit()
    n_bad = len(bad) - int(header)
    if strict and n_bad:
        first = int(bad[1] if header else bad[0])
        raise DataError(f"{path}: line {first + 1}: not a page (TOW,WN,SVID and 60 hexadecimal digits)")
    raw, line = raw[ok.to_numpy()], line[ok.to_numpy()]
    nibbles = np.frombuffer("".join(raw["hex"].str.strip()).encode(), np.uint8).reshape(len(raw), 60)
    values = np.where(nibbles >= ord("a"), nibbles - 87, np.where(nibbles >= ord("A"), nibbles - 55, nibbles - 48)).astype(np.uint8)
    bits = ((values[..., None] >> np.arange(3, -1, -1, dtype=np.uint8)) & 1).reshape(len(raw), 240)
    table = _table(raw["svid"].astype(int), raw["wn"].astype(int), raw["tow"].astype(int), np.full(len(raw), E1B), bits, line)
    return Pages(table, n_bad, str(path))


def ubx_page_bits(words: np.ndarray) -> np.ndarray:
    """(n, 8) u-blox 32-bit words → (n, 240) page bits (each half's 8 bits of padding removed)."""
    w = np.asarray(words, np.uint64)[:, :8]
    bits = ((w[..., None] >> np.arange(31, -1, -1, dtype=np.uint64)) & np.uint64(1)).astype(np.uint8).reshape(len(w), 256)
    return np.hstack([bits[:, :120], bits[:, 128:248]])


def read_ubx(path: str | os.PathLike, strict: bool = False) -> Pages:
    """The Galileo I/NAV pages of a u-blox log (RXM-SFRBX), timed by NAV-TIMEGAL.

    A page is labelled with the last valid NAV-TIMEGAL before it (its time of week rounded down to the page's
    even second, and its week); one page per satellite and signal is kept per label, and pages before the first
    label or repeated within one are counted as dropped. The frames are read block by block and selected with
    array operations (:func:`~tollcli.readers.ubx_frames.iter_frame_blocks`)."""
    from tollcli.io.sources import open_binary
    from tollcli.readers.nmea.line_reader import ReadStats
    from tollcli.readers.ubx_frames import iter_frame_blocks

    parts: list[dict] = []
    stats = ReadStats()
    try:
        with open_binary(str(path)) as stream:
            for block in iter_frame_blocks(stream, str(path), stats, strict):
                parts.append(_block_rows(block))
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    if stats.sentences == 0:
        raise DataError(f"{path}: no UBX messages")
    rows = {k: np.concatenate([p[k] for p in parts]) if parts else np.zeros(0, np.int64) for k in _ROW_KEYS}
    if not parts:
        rows["words"] = np.zeros((0, 8), np.uint64)
    return _pages_of_rows(rows, str(path))


_ROW_KEYS = ("is_time", "tow", "wn", "valid", "svid", "sig", "sig_byte", "signal_ok", "line", "words")


def _block_rows(block) -> dict:
    """The NAV-TIMEGAL and RXM-SFRBX (Galileo) frames of a block, in file order, as arrays."""
    data = np.frombuffer(block.buf, np.uint8)
    cls, ident = block.classes, block.ids
    length = block.ends - block.starts - 8
    payload = block.starts + 6
    is_time = (cls == _TIMEGAL[0]) & (ident == _TIMEGAL[1]) & (length >= 16)
    is_page = (cls == _SFRBX[0]) & (ident == _SFRBX[1]) & (length >= 40)
    is_page[is_page] = data[payload[is_page]] == 2  # gnssId: Galileo
    keep = np.flatnonzero(is_time | is_page)
    at = payload[keep]
    time_row = is_time[keep]

    def u(offset: int, n: int, dtype) -> np.ndarray:  # little-endian fields at payload offset, (rows,) of dtype
        idx = np.minimum(at[:, None] + offset + np.arange(n), len(data) - 1)
        return np.ascontiguousarray(data[idx]).view(dtype).reshape(len(at))

    gal_tow = u(4, 4, "<u4").astype(np.int64)
    wn = u(12, 2, "<i2").astype(np.int64)
    valid = (data[np.minimum(at + 15, len(data) - 1)] & 0x03) == 0x03  # galTowValid, galWnoValid
    sig = np.where(data[np.minimum(at + 6, len(data) - 1)] >= 2, data[np.minimum(at + 2, len(data) - 1)], 1).astype(np.int64)
    words_idx = np.minimum(at[:, None] + 8 + np.arange(32), len(data) - 1)
    words = np.ascontiguousarray(data[words_idx]).view("<u4").reshape(len(at), 8).astype(np.uint64)
    return {"is_time": time_row, "tow": gal_tow - (3 - gal_tow % 2), "wn": wn, "valid": time_row & valid,
            "svid": data[np.minimum(at + 1, len(data) - 1)].astype(np.int64), "sig": sig,
            "sig_byte": data[np.minimum(at + 2, len(data) - 1)].astype(np.int64), "signal_ok": np.isin(sig, list(_UBX_SIGNAL)),
            "line": block.first_number + keep.astype(np.int64), "words": words}  # fmt: skip


def _pages_of_rows(rows: dict, name: str) -> Pages:
    """Label the pages with the NAV-TIMEGAL before them and keep the first per satellite and signal (``read_ubx``)."""
    valid = rows["valid"]
    label_tow, label_wn = rows["tow"][valid], rows["wn"][valid]
    new_label = np.ones(len(label_tow), bool)
    new_label[1:] = (label_tow[1:] != label_tow[:-1]) | (label_wn[1:] != label_wn[:-1])
    label_id = np.full(len(valid), -1, np.int64)
    label_id[valid] = np.cumsum(new_label) - 1
    label_id = np.maximum.accumulate(label_id) if len(label_id) else label_id  # the label in force at each row
    first_of_label = np.flatnonzero(valid)[new_label]
    page = ~rows["is_time"] & rows["signal_ok"]
    timed = page & (label_id >= 0)
    idx = np.flatnonzero(timed)
    key = pd.DataFrame({"label": label_id[idx], "svid": rows["svid"][idx], "sig": rows["sig_byte"][idx]})  # (svId, sigId) as sent
    first = idx[~key.duplicated().to_numpy()]
    n_dropped = int(page.sum() - len(first))
    which = label_id[first]
    tow, wn = rows["tow"][first_of_label][which], rows["wn"][first_of_label][which]
    signal = np.array([_UBX_SIGNAL[int(k)] for k in rows["sig"][first]], dtype=object) if len(first) else np.zeros(0, object)
    bits = ubx_page_bits(rows["words"][first])
    return Pages(_table(rows["svid"][first], wn, tow, signal, bits, rows["line"][first]), n_dropped, name)


def read_pages(path: str | os.PathLike, strict: bool = False) -> Pages:
    """I/NAV pages from an ICD test-vector CSV or a u-blox log (told apart by their first bytes)."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(4096)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    if b"\xb5\x62" in head:
        return read_ubx(path, strict)
    return read_icd_csv(path, strict)
