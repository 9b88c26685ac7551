"""The TESLA key chain (OSNMA SIS ICD §6.4–6.5), the MAC functions and the MAC look-up table.

Times are Galileo system time in seconds since the GST origin (``wn·604800 + tow``); in hashes and MACs a
time is its 32 bits ``WN (12) ‖ TOW (20)``.

* Key ``i`` is received in the subframe ``GST_SF(i) = GST0 − 30 + 30·⌈i / NMACK⌉`` (the root key, index 0,
  at ``GST0 − 30``); ``K_{i−1} = trunc(KS, hash(K_i ‖ GST_SF(i−1) ‖ α))`` with the chain's hash (SHA-256 or
  SHA3-256). A received key is verified by hashing it down to the last verified key (:meth:`Chain.add_key`).
* A tag of subframe ``GST_SF`` is checked with key ``index(GST_SF) + 1`` (the next subframe's), ADKD 12
  (slow MAC) with key ``index + 11``.
* MAC: HMAC-SHA-256 or CMAC-AES over the bit string zero-padded to whole bytes, truncated to the tag length.
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass

from tollcli.gnss.osnma.bits import from_bytes, from_int, to_bytes
from tollcli.gnss.osnma.dsm import Kroot

WEEK_S = 604_800
#: the MACK message's length (bits) and that of a page's share of it
MACK_BITS, MACK_PAGE_BITS = 480, 32
#: MAC look-up table (ICD Annex C): MACLT → the tag slots of the subframes at GST % 60 == 0 and == 30
#: ("00S": ADKD 0 for the transmitting satellite, "E": any Galileo satellite, "G": reserved, "FLX": flexible)
MACLT = {
    27: ("00S 00E 00E 00E 12S 00E", "00S 00E 00E 04S 12S 00E"),
    28: ("00S 00E 00E 00E 00S 00E 00E 12S 00E 00E", "00S 00E 00E 00S 00E 00E 04S 12S 00E 00E"),
    29: ("00S 00E 12E 00G 12S 00E", "00S 00G 00E 04S 12S 00E"),
    31: ("00S 00E 00E 12S 00E", "00S 00E 00E 12S 04S"),
    32: ("00S 00E 00G 00S 00G 05S 12S 00E 12E 00E", "00S 00G 00E 00G 05S 00S 05E 04S 12S 00E"),
    33: ("00S 00E 04S 00E 12S 00E", "00S 00E 00E 12S 00E 12E"),
    34: ("00S FLX 04S FLX 12S 00E", "00S FLX 00E 12S 00E 12E"),
    35: ("00S FLX 04S FLX 12S FLX", "00S FLX FLX 12S FLX FLX"),
    36: ("00S FLX 04S FLX 12S", "00S FLX 00E 12S 12E"),
    37: ("00S 00E 04S 00E 12S", "00S 00E 00E 12S 12E"),
    38: ("00S FLX 04S FLX 12S", "00S FLX FLX 12S FLX"),
    39: ("00S FLX 04S FLX", "00S FLX 00E 12S"),
    40: ("00S 00E 04S 12S", "00S 00E 00E 12E"),
    41: ("00S FLX 04S FLX", "00S FLX FLX 12S"),
}


def gst_bits(gst_s: int) -> str:
    """GST seconds → ``WN (12 bits) ‖ TOW (20 bits)``."""
    wn, tow = divmod(gst_s, WEEK_S)
    return from_int(wn, 12) + from_int(tow, 20)


def maclt_slots(maclt: int, gst_sf_s: int) -> list[str] | None:
    """The tag slots of a subframe (None: a MACLT this table does not hold)."""
    entry = MACLT.get(maclt)
    return None if entry is None else entry[1 if gst_sf_s % 60 else 0].split()


@dataclass
class Key:
    index: int
    bits: str
    gst_sf_s: int  # the subframe it belongs to
    svid: int = 0


class Chain:
    """One TESLA chain, from a verified DSM-KROOT: parameters, MAC function and the last verified key."""

    def __init__(self, kroot: Kroot):
        self.kroot = kroot
        self.cid = kroot.cid
        self.nmack = max(kroot.nmack, 1)
        self.key_bits, self.tag_bits, self.maclt = kroot.key_bits, kroot.tag_bits, kroot.maclt
        self.alpha = kroot.alpha
        self.gst0_s = kroot.wn_k * WEEK_S + kroot.towh_k * 3600
        self.hash = {0: hashlib.sha256, 2: hashlib.sha3_256}.get(kroot.hf, hashlib.sha256)
        self.n_tags = (MACK_BITS - self.key_bits) // (self.tag_bits + 16)
        #: a key's first page within its subframe (s): the key follows the tags
        self.key_offset_s = ((self.tag_bits + 16) * self.n_tags // MACK_PAGE_BITS) * 2 + 1
        self.last = Key(0, kroot.kroot, self.gst0_s - 30)

    def gst_sf_of(self, index: int) -> int:
        return self.gst0_s - 30 if index == 0 else self.gst0_s - 30 + 30 * -(-index // self.nmack)

    def index_of(self, gst_sf_s: int) -> int:
        """The index of the key received in the subframe starting at ``gst_sf_s``."""
        return (gst_sf_s - self.gst0_s) // 30 * self.nmack + 1

    def previous(self, key: Key) -> Key:
        """The key one index below ``key``."""
        gst = self.gst_sf_of(key.index - 1)
        digest = self.hash(to_bytes(key.bits + gst_bits(gst) + self.alpha)).digest()
        return Key(key.index - 1, from_bytes(digest, self.key_bits), gst)

    def key_at(self, index: int) -> Key | None:
        """The verified key of ``index`` (hashed down from the last verified key), None if not yet known."""
        if index > self.last.index or index < 0:
            return None
        key = self.last
        while key.index > index:
            key = self.previous(key)
        return key

    def add_key(self, key: Key) -> tuple[bool, bool]:
        """(verified, new): a received key hashed down to the last verified one (or, if older, that one hashed
        down to it)."""
        if key.index > self.last.index:
            probe = key
            while probe.index > self.last.index:
                probe = self.previous(probe)
            if probe.bits == self.last.bits:
                self.last = key
                return True, True
            return False, False
        known = self.key_at(key.index)
        return known is not None and known.bits == key.bits, False

    def mac(self, key_bits: str, message: str) -> str:
        """HMAC-SHA-256 or CMAC-AES (as the chain's MF says) of a bit string, as bits."""
        if self.kroot.mf == 1:
            from cryptography.hazmat.primitives.cmac import CMAC
            from cryptography.hazmat.primitives.ciphers.algorithms import AES

            c = CMAC(AES(to_bytes(key_bits)))
            c.update(to_bytes(message))
            return from_bytes(c.finalize())
        return from_bytes(hmac.new(to_bytes(key_bits), to_bytes(message), hashlib.sha256).digest())
