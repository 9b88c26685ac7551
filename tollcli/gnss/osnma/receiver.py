"""The OSNMA receiver: pages in time order → what was verified and what failed (receiver guidelines §2–3).

Why this file is long: it is the state machine of the guidelines — start states (no key → public key →
root key verified), subframe assembly per satellite, HKROOT regeneration across satellites, DSM reassembly,
chain status changes, tags waiting for their key and MACSEQ, and the count of authenticated data — whose
steps share that state; each cryptographic step is a function of :mod:`.dsm`, :mod:`.tesla`, :mod:`.mack`
and :mod:`.navdata`.

The loop runs once per page (a state machine cannot be vectorized); its work per page is a few slices, and
the cryptography runs once per tag, key and signature.

Defaults are the guidelines' (and OSNMAlib's, the open reference implementation this is compared with in
``tests/test_osnma_icd.py``): the time-synchronisation bound ``sync_bound_s`` = 30 s (the receiver's clock
is known to within 30 s of GST: every tag may be used; above 30 s only slow-MAC ADKD 12 tags; above 330 s
none); data count as authenticated once ``min_tag_bits`` = 40 bits of tags verified them; a broken HKROOT
subframe is completed from the same DSM block of other satellites, tags of a partly received MACK are still
used, a key missing pages is completed from other satellites of the subframe, and Reed-Solomon words
complete the ephemeris.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from tollcli.gnss.osnma.bits import uint
from tollcli.gnss.osnma.dsm import NB_DK, NB_DP, NPKT_OAM, MerkleTree, PublicKey, hex_of, verify_kroot, verify_pkr
from tollcli.gnss.osnma.mack import Macseq, Tag, parse_mack, slot_accepts
from tollcli.gnss.osnma.navdata import ADKD_LENGTH, Adkd0Data, Adkd4Data, Block, ReedSolomonRecovery
from tollcli.gnss.osnma.pages import E1B, HKROOT_BITS, MACK_BITS
from tollcli.gnss.osnma.tesla import WEEK_S, Chain, Key, maclt_slots

COLD, WARM, STARTED, ALERT = "cold start", "public key", "started", "alert message"
NMAS_DONT_USE = "11"
ACTIVE_ADKD = (0, 4, 12)
FAILURE_COLUMNS = ["gst_s", "svid", "kind", "detail"]


@dataclass
class OsnmaSettings:
    merkle: MerkleTree
    keys: list[PublicKey] = field(default_factory=list)
    sync_bound_s: float = 30.0
    min_tag_bits: int = 40
    n_satellites: int = 36


@dataclass
class OsnmaResult:
    tags: pd.DataFrame  # one row per tag checked: gst_sf_s, prn_a, prn_d, adkd, cop, flx, tag0, dummy, verified, at_s
    data: pd.DataFrame  # one row each time data reached min_tag_bits or gained tags: adkd, prn_d, iod, first_sf_s, last_sf_s, bits, at_s
    kroots: pd.DataFrame  # gst_s, cid, pkid, gst0_s, verified
    keys: pd.DataFrame  # gst_sf_s, svid, index, verified, new, reconstructed
    failures: pd.DataFrame  # gst_s, svid, kind (tag, macseq, key, kroot, pkr, maclt), detail
    iods: pd.DataFrame  # svid, gst_s, iod, data_key: the data set each satellite's pages carried then (key: its words' digest)
    counts: dict = field(default_factory=dict)


class _Sat:
    __slots__ = ("hk", "mack", "osnma", "active", "processed")

    def __init__(self):
        self.reset()

    def reset(self):
        self.hk: list[str | None] = [None] * 15
        self.mack: list[str | None] = [None] * 15
        self.osnma = self.active = self.processed = False


class _Regenerator:
    """HKROOT blocks of broken subframes, merged across satellites transmitting the same DSM."""

    def __init__(self):
        self.dsm_id: int | None = None
        self.blocks: dict[int, list[str | None]] = {}

    def load(self, hk: list[str | None]) -> tuple[str | None, str | None]:
        bid = None
        if hk[1] is not None:
            bid, dsm_id = uint(hk[1][4:8]), uint(hk[1][:4])
            if dsm_id != self.dsm_id:
                self.dsm_id, self.blocks = dsm_id, {}
        whole = "".join(p for p in hk if p is not None)
        complete = whole if len(whole) == 120 else None
        if complete is None and bid is not None:
            kept = self.blocks.get(bid)
            if kept is None:
                self.blocks[bid] = list(hk)
            else:
                for k, page in enumerate(hk):
                    if kept[k] is None and page is not None:
                        kept[k] = page
        return complete, (hk[0][:2] if hk[0] is not None else None)

    def regenerated(self) -> list[str]:
        out = []
        for bid, block in list(self.blocks.items()):
            if all(p is not None for p in block):
                out.append("".join(block))
                del self.blocks[bid]
        return out


class _Dsm:
    def __init__(self, dsm_id: int):
        self.dsm_id, self.kroot = dsm_id, dsm_id < 12
        self.reset()

    def reset(self):
        self.blocks: dict[int, str] = {}
        self.total: int | None = None

    def load(self, hk: str) -> None:
        bid = uint(hk[12:16])
        self.blocks[bid] = hk[16:]
        if bid == 0:
            table = NB_DK if self.kroot else NB_DP
            self.total = table.get(uint(hk[16:20]), (None,))[0]

    def complete(self) -> bool:
        return self.total is not None and len(self.blocks) == self.total

    def message(self) -> str:
        out = "".join(self.blocks[k] for k in range(self.total))
        self.reset()
        return out


class _AuthData:
    __slots__ = ("bits", "first_sf_s", "last_sf_s", "iod", "new", "adkd", "prn_d", "data_key")

    def __init__(self, tag: Tag, iod: str | None, stream: str):
        self.bits, self.first_sf_s, self.last_sf_s = len(tag.value), tag.gst_sf_s, tag.gst_sf_s
        self.iod, self.new, self.adkd, self.prn_d = iod, True, tag.adkd, tag.prn_d
        self.data_key = data_key(stream)


def data_key(stream: str | None) -> str | None:
    """A short digest naming a data stream (the words a tag covers), to tell one data set from another."""
    return None if stream is None else hashlib.blake2b(stream.encode(), digest_size=8).hexdigest()


class Receiver:
    """Feed pages in time order with :meth:`page`; :meth:`result` gives the tables."""

    def __init__(self, settings: OsnmaSettings):
        self.s = settings
        self.keys: dict[int, PublicKey] = {k.pkid: k for k in settings.keys if k.verified}
        self.state = WARM if self.keys else COLD
        self.merkle_root = settings.merkle.root
        self.nma_status: str | None = None
        self.chain_status: int | None = None
        self.cid: int | None = None
        self.current_pkid: int | None = None
        self.last_nmas = "01"
        self.chain: Chain | None = None
        self.next_chain: Chain | None = None
        self.waiting_macks: list[tuple] = []
        self.dsms = {k: _Dsm(k) for k in range(16)}
        self.recent_dsm = {True: [], False: []}
        self.regen = _Regenerator()
        self.sats = {k: _Sat() for k in range(1, settings.n_satellites + 1)}
        self.adkd0 = {k: Adkd0Data() for k in range(1, settings.n_satellites + 1)}
        self.adkd4 = {k: Adkd4Data() for k in range(1, settings.n_satellites + 1)}
        self.rs = {k: ReedSolomonRecovery() for k in range(1, settings.n_satellites + 1)}
        self.awaiting_tags: list[Tag] = []
        self.awaiting_macseq: list[Macseq] = []
        self.auth: dict[tuple, _AuthData] = {}
        self.current_sf: int | None = None
        self.last_s: int | None = None
        self.now_s = 0
        self.rows = {"tags": [], "data": [], "kroots": [], "keys": [], "failures": [], "iods": []}
        self.counts = {"pages": 0, "crc_failed": 0, "time_backwards": 0, "broken_hkroot": 0, "alert_or_dummy": 0,
                       "rs_errors": 0, "first_authenticated_fix_s": None}  # fmt: skip
        self._auth_sats: set[int] = set()

    # ---- pages -----------------------------------------------------------------------------------------
    def page(self, svid: int, gst_s: int, band: str, bits: str, crc_ok: bool) -> None:
        self.counts["pages"] += 1
        if svid not in self.sats:
            return
        if bits[1] == "1" or bits[2:8] == "111111":
            self.counts["alert_or_dummy"] += 1
            return
        if not crc_ok:
            self.counts["crc_failed"] += 1
            return
        if self.last_s is not None and gst_s < self.last_s:
            self.counts["time_backwards"] += 1
            return
        self.last_s = self.now_s = gst_s
        gst_sf = gst_s - gst_s % 30
        if self.current_sf is None:
            self.current_sf = gst_sf
        if gst_sf > self.current_sf:
            self._end_of_subframe()
            self.current_sf = gst_sf
        sat = self.sats[svid]
        sat.active = True
        field_bits = bits[138:178]
        if band == E1B and "1" in field_bits:
            sat.osnma = True
            k = (gst_s % 30) // 2
            sat.hk[k], sat.mack[k] = bits[HKROOT_BITS], bits[MACK_BITS]
        self._nav_page(svid, gst_s, band, bits)
        if gst_s % 30 == 29:
            self._end_of_satellite_subframe(self.current_sf, svid, sat)
            sat.processed = True

    def _nav_page(self, svid: int, gst_s: int, band: str, bits: str) -> None:
        word_type = uint(bits[2:8])
        word = bits[2:114] + bits[122:138]
        if word_type in (1, 2, 3, 4, 5):
            self.adkd0[svid].add_word(word_type, word, gst_s)
        elif word_type == 6 or (word_type == 10 and band == E1B):
            self.adkd4[svid].add_word(word_type, word, gst_s)
        if word_type in (1, 2, 3, 4, 5, 6, 10, 17, 18, 19, 20):
            rs = self.rs[svid]
            rs.add_word(word_type, word, gst_s)
            try:
                recovered = rs.recover()
            except ValueError as exc:
                self.counts["rs_errors"] += 1
                self._fail(svid, "reed_solomon", str(exc))
                recovered = {}
            for wt, w in recovered.items():
                self.adkd0[svid].add_word(wt, w, gst_s)
        if word_type in (1, 2, 3, 4, 5, 17, 18, 19, 20):
            newest = self.adkd0[svid].blocks[-1] if self.adkd0[svid].blocks else None
            if newest is not None:  # the data set the satellite sends now: its IOD and words (key None until complete)
                self.rows["iods"].append((svid, gst_s, newest.iod, data_key(newest.stream)))

    def _end_of_subframe(self) -> None:
        for svid, sat in self.sats.items():
            if sat.active and not sat.processed:
                self._end_of_satellite_subframe(self.current_sf, svid, sat)
        for sat in self.sats.values():
            if sat.active:
                sat.reset()

    def _end_of_satellite_subframe(self, gst_sf: int, svid: int, sat: _Sat) -> None:
        if not sat.osnma:
            return
        hk, nmas = self.regen.load(sat.hk)
        if nmas is not None:
            self.last_nmas = nmas
        if hk is not None:
            self._hkroot(hk, consecutive=True)
        else:
            self.counts["broken_hkroot"] += 1
            for block in self.regen.regenerated():
                self._hkroot(block)
        self._mack(sat.mack, gst_sf, svid)

    # ---- HKROOT: DSM-PKR and DSM-KROOT --------------------------------------------------------------------
    def _hkroot(self, hk: str, consecutive: bool = False) -> None:
        if self.state == ALERT:
            return
        header, dsm_id = hk[:8], uint(hk[8:12])
        recent = self.recent_dsm[dsm_id < 12]
        if dsm_id not in recent:
            recent.append(dsm_id)
        if len(recent) > 2:
            self.dsms[recent.pop(0)].reset()
        dsm = self.dsms[dsm_id]
        dsm.load(hk)
        if consecutive and self.chain_status == 2:  # end of chain: follow the header's chain in force
            cid = uint(header[2:4])
            if cid != self.cid:
                self.cid = cid
                if self.next_chain is not None and self.next_chain.cid == cid:
                    self.chain, self.next_chain = self.next_chain, None
        if dsm.complete():
            message = dsm.message()
            self._kroot(header, message) if dsm.kroot else self._pkr(message)

    def _pkr(self, message: str) -> None:
        r = verify_pkr(message, self.merkle_root)
        if not r.verified:
            self._fail(0, "pkr", f"DSM-PKR rejected: {r.why}")
            return
        if r.key is None or uint(message[1032:1036]) == NPKT_OAM:
            self._fallback(ALERT)
            return
        self.keys.setdefault(r.key.pkid, r.key)
        if self.state == COLD:
            self.state = WARM

    def _kroot(self, header: str, message: str) -> None:
        if self.state == COLD:
            return
        kroot = verify_kroot(header, message, self.keys)
        gst0 = kroot.wn_k * WEEK_S + kroot.towh_k * 3600
        if kroot.why.startswith("no verified public key"):
            if self.state == WARM:
                self._fallback(COLD)
            return
        self.rows["kroots"].append((self.now_s, kroot.cid, kroot.pkid, gst0, kroot.verified))
        if not kroot.verified:
            self._fail(0, "kroot", f"DSM-KROOT of chain {kroot.cid} (PKID {kroot.pkid}) rejected: {kroot.why}")
            if self.state == WARM:
                self._fallback(COLD)
            return
        nmas, cid, cpks = header[:2], uint(header[2:4]), uint(header[4:7])
        self.nma_status, self.cid, self.chain_status = nmas, cid, cpks
        if cpks in (1, 6) or (cpks == 2 and cid == kroot.cid) or (cpks in (3, 5) and nmas != NMAS_DONT_USE):
            self._kroot_in_force(kroot)
        elif cpks == 2:
            self.next_chain = Chain(kroot)
        elif cpks == 3 and self.state == STARTED and self.chain is not None and cid == self.chain.cid:
            self._fallback(WARM, cpks)
        elif cpks == 4:
            self._kroot_in_force(kroot)
            if kroot.pkid != self.current_pkid:
                self.keys.pop(self.current_pkid, None)
                self.current_pkid = kroot.pkid
        elif cpks == 5 and self.state == STARTED:
            self._fallback(COLD, cpks)
        elif cpks == 7:
            self._fallback(ALERT, cpks)

    def _kroot_in_force(self, kroot) -> None:
        if self.state != STARTED:
            self.chain, self.current_pkid, self.state = Chain(kroot), kroot.pkid, STARTED
        elif self.chain is None or kroot.cid != self.chain.cid:
            self.chain, self.current_pkid, self.next_chain = Chain(kroot), kroot.pkid, None

    def _fallback(self, state: str, cpks: int = 1) -> None:
        self.state, self.chain_status = state, cpks
        self.chain = self.next_chain = None
        self.waiting_macks, self.current_pkid = [], None
        if state in (COLD, ALERT):
            self.keys = {}
        if state == ALERT:
            self.nma_status = NMAS_DONT_USE

    # ---- MACK: tags and keys ----------------------------------------------------------------------------------
    def _mack(self, pages: list[str | None], gst_sf: int, svid: int) -> None:
        if self.nma_status == NMAS_DONT_USE:
            self.waiting_macks = []
            return
        if self.state in (COLD, WARM):
            self.waiting_macks.append((list(pages), gst_sf, svid, self.last_nmas))
            return
        while self.waiting_macks:
            self._one_mack(*self.waiting_macks.pop(0))
        self._one_mack(pages, gst_sf, svid, self.last_nmas)

    def _one_mack(self, pages: list[str | None], gst_sf: int, svid: int, nmas: str) -> None:
        chain = self.chain
        if chain is None:
            return
        mack = parse_mack(pages, chain, gst_sf, svid, nmas)
        self._load_tags(mack, chain, gst_sf)
        key_pages, reconstructed = mack.key_pages, False
        missing = any(p is None for p in key_pages)
        if missing:  # complete the key from other satellites of this subframe (once per subframe)
            state = getattr(chain, "_regen", None)
            if state is None or state[0] != gst_sf:
                chain._regen = [gst_sf, list(key_pages), False]
            elif not state[2]:
                kept = state[1]
                for k, page in enumerate(key_pages):
                    if kept[k] is None and page is not None:
                        kept[k] = page
                missing = any(p is None for p in kept)
                key_pages, reconstructed, state[2] = kept, True, not missing
        if missing:
            return
        a, b = mack.key_slice
        index = chain.index_of(gst_sf)
        if index < 0:
            return
        key = Key(index, "".join(key_pages)[a:b], gst_sf, svid)
        verified, new = chain.add_key(key)
        self.rows["keys"].append((gst_sf, svid, index, verified, new, reconstructed))
        if not verified:
            self._fail(svid, "key", f"TESLA key {index} of subframe {_gst_text(gst_sf)} does not hash to the verified chain "
                                    f"(last verified key {chain.last.index})")  # fmt: skip
        elif new:
            self._update_tags(chain)

    def _load_tags(self, mack, chain: Chain, gst_sf: int) -> None:
        slots = maclt_slots(chain.maclt, gst_sf)
        if slots is None:
            self._fail(0, "maclt", f"MAC look-up table {chain.maclt} is not one of the ICD's")
            return
        listed, flx, flx_missing = [], [], False
        for tag, slot in zip(mack.tags, slots):
            if slot != "FLX":
                if tag is not None:
                    if slot_accepts(slot, tag):
                        listed.append(tag)
                    else:
                        self._fail(tag.prn_a, "maclt", f"tag {tag.ctr} (PRN_D {tag.prn_d}, ADKD {tag.adkd}) does not fit slot {slot} "
                                                       f"of MAC look-up table {chain.maclt}")  # fmt: skip
            elif tag is None:
                flx_missing = True
            else:
                tag.is_flx = True
                flx.append(tag)
        index = chain.index_of(gst_sf)
        for tag in listed:
            tag.key_index = index + (11 if tag.adkd == 12 else 1)
        if mack.macseq is not None and not flx_missing:
            mack.macseq.flx, mack.macseq.key_index = flx, index + 1
            self.awaiting_macseq.append(mack.macseq)
        for tag in listed:
            if tag.adkd in ACTIVE_ADKD and 1 <= tag.prn_d <= self.s.n_satellites:
                self.awaiting_tags.append(tag)

    def _update_tags(self, chain: Chain) -> None:
        waiting: list[Macseq] = []  # (lists rebuilt in one pass: a tag's equality compares every field)
        for macseq in self.awaiting_macseq:
            key = chain.key_at(macseq.key_index)
            if key is None:
                waiting.append(macseq)
                continue
            if chain.mac(key.bits, macseq.message())[:12] == macseq.value:
                index = chain.index_of(macseq.gst_sf_s)
                for tag in macseq.flx:
                    tag.key_index = index + (11 if tag.adkd == 12 else 1)
                self.awaiting_tags.extend(macseq.flx)
            else:
                self._fail(macseq.prn_a, "macseq", f"MACSEQ of subframe {_gst_text(macseq.gst_sf_s)} does not verify")
        self.awaiting_macseq = waiting
        tags, still = self.awaiting_tags, []
        for k, tag in enumerate(tags):
            if self.s.sync_bound_s > 330 or (self.s.sync_bound_s > 30 and tag.adkd != 12):
                continue
            key = chain.key_at(tag.key_index)
            if key is None:
                still.append(tag)
                continue
            data = self._data_for(tag, chain, key)
            if data is not None:
                self._verify(tag, data, chain, key)
                if self.nma_status == NMAS_DONT_USE:
                    self.awaiting_tags = still + tags[k + 1 :]
                    return
        self.awaiting_tags = still
        self._check_data()

    def _data_for(self, tag: Tag, chain: Chain, key: Key) -> tuple[str, Block | None] | None:
        if tag.dummy:
            return "0" * ADKD_LENGTH[tag.adkd], None
        if tag.adkd in (0, 12):
            start = chain.gst_sf_of(key.index) + chain.key_offset_s
            block = self.adkd0[tag.prn_d].data_for(tag.gst_sf_s, tag.cop, start, self.s.sync_bound_s, tag.prn_a != tag.prn_d)
            return None if block is None else (block.stream, block)
        if tag.adkd == 4:
            stream = self.adkd4[tag.prn_d].data_for(tag.gst_sf_s, tag.cop)
            return None if stream is None else (stream, None)
        return None

    def _verify(self, tag: Tag, data: tuple[str, Block | None], chain: Chain, key: Key) -> None:
        stream, block = data
        ok = chain.mac(key.bits, tag.message(stream))[: chain.tag_bits] == tag.value
        iod = block.iod if block is not None else None
        self.rows["tags"].append((tag.gst_sf_s, tag.prn_a, tag.prn_d, tag.adkd, tag.cop, tag.is_flx, tag.is_tag0, tag.dummy, ok,
                                  self.now_s, iod))  # fmt: skip
        if not ok:
            what = "tag 0" if tag.is_tag0 else f"tag {tag.ctr}"
            self._fail(tag.prn_d if tag.prn_d <= self.s.n_satellites else tag.prn_a, "tag",
                       f"{what} from E{tag.prn_a:02d} over ADKD {tag.adkd} data of E{tag.prn_d:02d} (subframe {_gst_text(tag.gst_sf_s)}, "
                       f"COP {tag.cop}) does not verify")  # fmt: skip
            return
        if block is not None and tag.adkd == 0:
            block.last_cop, block.last_cop_s = tag.cop, tag.gst_sf_s
        if tag.nmas == NMAS_DONT_USE:
            self.nma_status = NMAS_DONT_USE
        if not tag.dummy:
            key_ = (tag.adkd, tag.prn_d, stream)
            if key_ in self.auth:
                a = self.auth[key_]
                a.bits, a.last_sf_s, a.new = a.bits + len(tag.value), tag.gst_sf_s, True
            else:
                self.auth[key_] = _AuthData(tag, iod if tag.adkd != 4 else None, stream)

    def _check_data(self) -> None:
        for a in self.auth.values():
            if a.new and a.bits >= self.s.min_tag_bits:
                a.new = False
                self.rows["data"].append((a.adkd, a.prn_d, a.iod, a.first_sf_s, a.last_sf_s, a.bits, self.now_s, a.data_key))
                if a.adkd != 4 and a.prn_d not in self._auth_sats:
                    self._auth_sats.add(a.prn_d)
                    if len(self._auth_sats) == 4:
                        self.counts["first_authenticated_fix_s"] = self.now_s
        for data in self.adkd0.values():
            data.keep_newest_if_confirmed()

    def _fail(self, svid: int, kind: str, detail: str) -> None:
        self.rows["failures"].append((self.now_s, svid, kind, detail))

    # ---- output -----------------------------------------------------------------------------------------------
    def result(self) -> OsnmaResult:
        r = self.rows
        tags = pd.DataFrame(r["tags"], columns=["gst_sf_s", "prn_a", "prn_d", "adkd", "cop", "flx", "tag0", "dummy", "verified", "at_s", "iod"])
        data = pd.DataFrame(r["data"], columns=["adkd", "prn_d", "iod", "first_sf_s", "last_sf_s", "bits", "at_s", "data_key"])
        kroots = pd.DataFrame(r["kroots"], columns=["gst_s", "cid", "pkid", "gst0_s", "verified"])
        keys = pd.DataFrame(r["keys"], columns=["gst_sf_s", "svid", "index", "verified", "new", "reconstructed"])
        failures = pd.DataFrame(r["failures"], columns=FAILURE_COLUMNS)
        iods = pd.DataFrame(r["iods"], columns=["svid", "gst_s", "iod", "data_key"])
        counts = dict(self.counts, tags_authenticated=int(tags["verified"].sum()) if len(tags) else 0,
                      data_authenticated=len(data), kroots_authenticated=int(kroots["verified"].sum()) if len(kroots) else 0,
                      failures=len(failures), state=self.state)  # fmt: skip
        return OsnmaResult(tags, data, kroots, keys, failures, iods, counts)


def _gst_text(gst_s: int) -> str:
    wn, tow = divmod(int(gst_s), WEEK_S)
    return f"WN {wn} TOW {tow}"


def run_osnma(pages: pd.DataFrame, settings: OsnmaSettings) -> OsnmaResult:
    """All pages of a table (:mod:`.pages`) through one receiver, in the table's order."""
    receiver = Receiver(settings)
    gst = (pages["wn"].to_numpy(np.int64) * WEEK_S + pages["tow_s"].to_numpy(np.int64)).tolist()
    for svid, t, band, bits, crc in zip(pages["svid"].tolist(), gst, pages["band"].tolist(), pages["bits"].tolist(), pages["crc_ok"].tolist()):
        receiver.page(svid, t, band, bits, crc)
    return receiver.result()


__all__ = ["OsnmaResult", "OsnmaSettings", "Receiver", "run_osnma", "hex_of"]
