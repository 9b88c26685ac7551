"""MACK messages (OSNMA SIS ICD §3.3): a subframe's 15 × 32 bits → tags with their info, and the TESLA key.

The message is ``TAG0 (TS) ‖ MACSEQ (12) ‖ COP (4)``, then ``n`` tags of ``TS`` bits each followed by
``PRN_D (8) ‖ ADKD (4) ‖ COP (4)``, then the key (KS bits), ``n = (480 − KS) // (TS + 16)``. A tag whose pages
were not all received is left out; the key may be completed from other satellites of the same subframe
(all transmit the same key).

What a tag authenticates (§6.4): ``PRN_D ‖ PRN_A ‖ GST_SF ‖ CTR ‖ NMAS ‖ navdata`` (tag 0: without ``PRN_D``,
``CTR`` = 1); the MACSEQ: ``PRN_A ‖ GST_SF`` and the ``PRN_D ‖ ADKD ‖ COP`` of each flexible tag.
"""

from __future__ import annotations

from dataclasses import dataclass

from tollcli.gnss.osnma.bits import from_int, uint
from tollcli.gnss.osnma.tesla import MACK_PAGE_BITS, Chain, gst_bits


@dataclass
class Tag:
    value: str
    prn_a: int
    prn_d: int
    adkd: int
    cop: int
    ctr: int  # 1 for tag 0
    gst_sf_s: int
    nmas: str  # 2 bits
    is_tag0: bool = False
    is_flx: bool = False
    key_index: int = 0

    @property
    def dummy(self) -> bool:
        return self.cop == 0

    def message(self, navdata: str) -> str:
        head = from_int(self.prn_a, 8) if self.is_tag0 else from_int(self.prn_d, 8) + from_int(self.prn_a, 8)
        return head + gst_bits(self.gst_sf_s) + from_int(self.ctr, 8) + self.nmas + navdata


@dataclass
class Macseq:
    value: str
    prn_a: int
    gst_sf_s: int
    flx: list[Tag]
    key_index: int = 0

    def message(self) -> str:
        return from_int(self.prn_a, 8) + gst_bits(self.gst_sf_s) + "".join(
            from_int(t.prn_d, 8) + from_int(t.adkd, 4) + from_int(t.cop, 4) for t in self.flx)


def _span(pages: list[str | None], start: int, size: int) -> str | None:
    """Bits ``start … start + size`` of the message, None when a page they lie in is missing."""
    first, last = start // MACK_PAGE_BITS, (start + size - 1) // MACK_PAGE_BITS
    chunk = pages[first : last + 1]
    if any(p is None for p in chunk):
        return None
    joined = "".join(chunk)
    return joined[start - first * MACK_PAGE_BITS : start - first * MACK_PAGE_BITS + size]


@dataclass
class Mack:
    tags: list[Tag | None]  # tag 0 first; None where pages were missing
    macseq: Macseq | None
    key_pages: list[str | None]
    key_slice: tuple[int, int]


def parse_mack(pages: list[str | None], chain: Chain, gst_sf_s: int, prn_a: int, nmas: str) -> Mack:
    """A subframe's MACK pages (None where missing) → tags and the key's pages."""
    size = chain.tag_bits + 16
    tags: list[Tag | None] = []
    macseq = None
    for k in range(chain.n_tags):
        bits = _span(pages, k * size, size)
        if bits is None:
            tags.append(None)
            continue
        value, info = bits[: chain.tag_bits], bits[chain.tag_bits :]
        if k == 0:
            tags.append(Tag(value, prn_a, prn_a, 0, uint(info[12:16]), 1, gst_sf_s, nmas, is_tag0=True))
            macseq = Macseq(info[:12], prn_a, gst_sf_s, [])
        else:
            tags.append(Tag(value, prn_a, uint(info[:8]), uint(info[8:12]), uint(info[12:16]), k + 1, gst_sf_s, nmas))
    start = chain.n_tags * size
    first, last = start // MACK_PAGE_BITS, (start + chain.key_bits - 1) // MACK_PAGE_BITS
    offset = start - first * MACK_PAGE_BITS
    return Mack(tags, macseq, list(pages[first : last + 1]), (offset, offset + chain.key_bits))


def slot_accepts(slot: str, tag: Tag) -> bool:
    """Whether a tag fits its MAC look-up table slot (ADKD, and S: own satellite, E: a Galileo one, G: reserved)."""
    if int(slot[:2]) != tag.adkd:
        return False
    kind = slot[2]
    return ((kind == "S" and tag.prn_a == tag.prn_d) or (kind == "E" and 1 <= tag.prn_d <= 36)
            or (kind in "SE" and tag.prn_d == 255) or (kind == "G" and 64 <= tag.prn_d < 96))  # fmt: skip
