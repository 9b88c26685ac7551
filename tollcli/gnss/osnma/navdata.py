"""The navigation data each ADKD authenticates, kept per satellite as pages arrive (receiver guidelines §3).

* ADKD 0 and 12 (ephemeris, clock, status): word types 1–5 of one issue of data — bits 6–125 of words 1,
  2 and 4, 6–127 of word 3, 6–72 of word 5 (549 bits). A *data block* is one IOD's words: it is complete
  once all five arrived (``completed_s``); a word type 5 that changes under the same IOD starts a new block,
  and so does (unlike OSNMAlib, which keeps the first) a word type 1–4 that differs from the one kept under
  its IOD: the words a position would use are the words a tag must have verified.
* ADKD 4 (GST–UTC and GST–GPS conversion): bits 6–104 of word 6 and 86–127 of word 10 (141 bits); word 10
  from E1-B only (it may change mid-subframe and E5b carries the stale one).
* A tag with cut-off point COP authenticates the data the satellite transmitted within COP subframes before
  the tag's subframe, and only if those data were complete before its key could have been known
  (``completed < key time − the time-synchronisation bound``); a tag of another satellite may also cover
  the last data seen of a satellite no longer tracked.
* Reed-Solomon outer code (Galileo OS SIS ICD 2.1 §4.3.5): word types 17–20 carry parity over words 1–4
  (shortened RS(118, 58) over GF(2⁸), primitive polynomial 0x11D, first root 1); any four of the eight
  words give the other four, so a block can complete before all its words arrived.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: word type → (first bit, end bit) of the word's part of the authenticated data
ADKD0_BITS = {1: (6, 126), 2: (6, 126), 3: (6, 128), 4: (6, 126), 5: (6, 73)}
ADKD4_BITS = {6: (6, 105), 10: (86, 128)}
ADKD_LENGTH = {0: 549, 12: 549, 4: 141}
FOUR_HOURS_S = 4 * 3600


@dataclass
class Block:
    """One IOD's ADKD 0/12 words."""

    start_s: int
    iod: str | None = None
    words: dict[int, str] = field(default_factory=dict)
    stream: str | None = None
    last_update_s: int = 0
    completed_s: int | None = None
    last_cop: int = 0
    last_cop_s: int = 0

    def __post_init__(self):
        self.last_update_s = self.start_s

    def add(self, word_type: int, data: str, gst_s: int) -> None:
        self.last_update_s = gst_s
        if word_type != 5:
            self.iod = data[:10]
        self.words[word_type] = data
        if self.completed_s is None and len(self.words) == 5:
            self.completed_s = gst_s
            self.stream = "".join(self.words[k] for k in range(1, 6))


class Adkd0Data:
    """A satellite's ADKD 0/12 data blocks, oldest first."""

    def __init__(self):
        self.blocks: list[Block] = []

    def add_word(self, word_type: int, word: str, gst_s: int) -> None:
        a, b = ADKD0_BITS[word_type]
        data = word[a:b]
        if word_type != 5:
            iod = data[:10]
            last = self.blocks[-1] if self.blocks else None
            if last is None or last.iod != iod or gst_s - last.last_update_s > FOUR_HOURS_S:
                block = Block(gst_s)
                block.add(word_type, data, gst_s)
                self.blocks.append(block)
            elif last.words.get(word_type, data) != data:
                # the same IOD with other data: not the data signed before (a forgery, or a receiver fault):
                # a new block, which tags must authenticate anew
                last.last_update_s = gst_s - gst_s % 30 - 1
                block = Block(gst_s, iod=last.iod, words=dict(last.words))
                block.add(word_type, data, gst_s)
                self.blocks.append(block)
            else:
                last.add(word_type, data, gst_s)
        elif self.blocks and gst_s - gst_s % 30 == self.blocks[-1].last_update_s - self.blocks[-1].last_update_s % 30:
            last = self.blocks[-1]  # a word 5 joins the IOD seen in the same subframe
            five = last.words.get(5)
            if five is None:
                last.add(5, data, gst_s)
            elif five != data:
                last.last_update_s = gst_s - gst_s % 30 - 1
                block = Block(gst_s, iod=last.iod, words=dict(last.words))
                block.add(5, data, gst_s)
                self.blocks.append(block)
        self._drop_incomplete()

    def _drop_incomplete(self) -> None:
        """A block that never completed is dropped once a newer one exists (in the order blocks were kept)."""
        behind = False
        for k, block in enumerate(list(self.blocks)):
            if behind:
                self.blocks.pop(k - 1)
            if block.completed_s is None:
                behind = True

    def data_for(self, tag_sf_s: int, cop: int, key_start_s: int, sync_bound_s: int, cross: bool) -> Block | None:
        """The block a tag (subframe, COP) covers, if its data were complete before the key could be known."""
        limit = tag_sf_s - 30 * cop
        for block in self.blocks:
            if block.completed_s is None:
                break
            if limit <= block.start_s < tag_sf_s:
                return None if block.completed_s >= key_start_s - sync_bound_s else block
            if block.start_s < limit < block.last_update_s:
                return block
        if cross and self.blocks:
            last = self.blocks[-1]
            if cop >= last.last_cop and last.start_s < tag_sf_s and last.last_cop_s > tag_sf_s - last.last_cop * 30:
                return last
        return None

    def keep_newest_if_confirmed(self) -> None:
        """Once the newest block was authenticated with COP > 11, no slow-MAC tag can point to older ones."""
        if len(self.blocks) >= 2 and self.blocks[-1].last_cop > 11:
            del self.blocks[:-1]


@dataclass
class Word:
    start_s: int
    data: str
    last_update_s: int


class Adkd4Data:
    """A satellite's last two distinct words 6 and 10 (ADKD 4)."""

    def __init__(self):
        self.words: dict[int, list[Word]] = {6: [], 10: []}

    def add_word(self, word_type: int, word: str, gst_s: int) -> None:
        a, b = ADKD4_BITS[word_type]
        data = word[a:b]
        kept = self.words[word_type]
        if kept and kept[-1].data == data:
            kept[-1].last_update_s = gst_s
        else:
            kept.append(Word(gst_s, data, gst_s))
            if len(kept) > 2:
                kept.pop(0)

    def data_for(self, tag_sf_s: int, cop: int) -> str | None:
        limit = tag_sf_s - 30 * cop
        found = {6: None, 10: None}
        for word_type, kept in self.words.items():
            for word in kept:
                if limit <= word.start_s < tag_sf_s:
                    found[word_type] = word.data
                elif word.start_s < limit < word.last_update_s:
                    found[word_type] = word.data
                    break
        return found[6] + found[10] if found[6] and found[10] else None


class ReedSolomonRecovery:
    """A satellite's words 1–4 and 17–20 of one IOD; four of them recover the rest."""

    CED, PARITY = (1, 2, 3, 4), (17, 18, 19, 20)

    def __init__(self):
        self.last_s = 0
        self.reset()

    def reset(self, iod: str | None = None, iod_lsb: str | None = None) -> None:
        self.iod, self.iod_lsb = iod, iod[-2:] if iod else iod_lsb
        self.ced: list[str | None] = [None] * 4
        self.parity: list[str | None] = [None] * 4

    def add_word(self, word_type: int, word: str, gst_s: int) -> None:
        if gst_s > self.last_s + 1800:
            self.reset()
        self.last_s = gst_s
        if word_type in self.CED:
            iod = word[6:16]
            if (self.iod is not None and self.iod != iod) or self.iod_lsb != iod[-2:]:
                self.reset(iod=iod)
            elif self.iod is None:
                self.iod = iod
            self.ced[word_type - 1] = word
        elif word_type in self.PARITY:
            lsb = word[14:16]
            if self.iod_lsb != lsb:
                self.reset(iod_lsb=lsb)
            self.parity[word_type - 17] = word

    def recover(self) -> dict[int, str]:
        """The missing words 1–4 (empty when all are there or fewer than four of the eight are); raises
        ``ValueError`` when the code words disagree."""
        have = sum(w is not None for w in self.ced)
        if have == 4 or have + sum(w is not None for w in self.parity) < 4:
            return {}
        return self._decode()

    def _decode(self) -> dict[int, str]:
        from tollcli.gnss.osnma.reed_solomon import erasure_decode

        info = ["0"] * (58 * 8)
        if self.ced[0] is not None:
            w = self.ced[0]
            info[0:128] = w[:128]
            info[6:8], info[8:16] = w[14:16], w[6:14]
        else:
            info[0:8] = "000001" + self.iod_lsb
        for k, w in enumerate(self.ced[1:]):
            if w is not None:
                info[128 + 112 * k : 128 + 112 * (k + 1)] = w[16:128]
        parity = ["0"] * (60 * 8)
        for k, w in enumerate(self.parity):
            if w is not None:
                parity[120 * k : 120 * k + 8] = w[6:14]
                parity[120 * k + 8 : 120 * (k + 1)] = w[16:128]
        code = bytes(int("".join(info[8 * k : 8 * k + 8]), 2) for k in range(58))
        code += bytes(int("".join(parity[8 * k : 8 * k + 8]), 2) for k in range(60))
        erasures = []
        for k, w in enumerate(self.ced):
            if w is None:
                erasures.extend(range(1, 16) if k == 0 else range(16 + 14 * (k - 1), 16 + 14 * k))
        for k, w in enumerate(self.parity):
            if w is None:
                erasures.extend(range(58 + 15 * k, 58 + 15 * (k + 1)))
        swapped = code[:58][::-1] + code[58:][::-1]  # the library's order: each vector reversed
        positions = [57 - i if i <= 57 else 175 - i for i in erasures]
        full = erasure_decode(swapped, positions)  # the fast path: no symbol received in error
        if full is None:  # a symbol received in error, or beyond the fast path: errors and erasures by reedsolo
            import reedsolo

            try:
                _, full, _ = _CODEC(reedsolo).decode(bytearray(swapped), erase_pos=positions)
            except reedsolo.ReedSolomonError as exc:
                raise ValueError(f"Reed-Solomon decoding failed: {exc}") from None
            full = bytes(full)
        full = full[:58][::-1] + full[58:][::-1]
        bits = "".join(format(b, "08b") for b in full)
        iod = bits[8:16] + bits[6:8]
        if self.iod_lsb != bits[6:8] or (self.iod is not None and self.iod != iod):
            raise ValueError("Reed-Solomon recovered IOD disagrees with the words received")
        self.iod = iod
        words = ["000001" + iod + bits[16:128]] + ["{:06b}".format(k + 2) + iod + bits[128 + 112 * k : 240 + 112 * k] for k in range(3)]
        out = {}
        for k, (kept, got) in enumerate(zip(self.ced, words)):
            if kept is None:
                self.ced[k] = got
                out[k + 1] = got
            elif kept != got:
                raise ValueError(f"Reed-Solomon recovered word {k + 1} disagrees with the word received")
        return out


_RS = None


def _CODEC(reedsolo):  # noqa: N802 - a cached constructor
    global _RS
    if _RS is None:
        _RS = reedsolo.RSCodec(60, nsize=255, fcr=1, prim=0x11D)
    return _RS
