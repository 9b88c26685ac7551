"""Bit strings as Python ``str`` of '0'/'1' (slicing and joining are the operations OSNMA needs), and their bytes.

MAC and hash inputs whose length is not a multiple of 8 are padded with zero bits at the end
(OSNMA SIS ICD §6.4: the padding ``P3``)."""

from __future__ import annotations


def from_hex(text: str, n_bits: int | None = None) -> str:
    """Hexadecimal text → bit string (``n_bits`` long, default 4 per digit)."""
    n = 4 * len(text) if n_bits is None else n_bits
    return format(int(text, 16), f"0{4 * len(text)}b")[:n] if text else ""


def from_int(value: int, n_bits: int) -> str:
    """An unsigned integer → its ``n_bits`` most significant bit first."""
    return format(value & ((1 << n_bits) - 1), f"0{n_bits}b")


def to_bytes(bits: str) -> bytes:
    """A bit string → bytes, zero-padded at the end to a whole byte."""
    if not bits:
        return b""
    pad = (-len(bits)) % 8
    return int(bits + "0" * pad, 2).to_bytes((len(bits) + pad) // 8, "big")


def from_bytes(data: bytes, n_bits: int | None = None) -> str:
    """Bytes → bit string (the first ``n_bits``, default all)."""
    bits = format(int.from_bytes(data, "big"), f"0{8 * len(data)}b") if data else ""
    return bits if n_bits is None else bits[:n_bits]


def uint(bits: str) -> int:
    """A bit string → unsigned integer (0 for the empty string)."""
    return int(bits, 2) if bits else 0
