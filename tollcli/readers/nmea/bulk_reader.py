"""The fast path of the NMEA reader: a block of bytes → finished epochs, decoded in bulk.

Per block (≈ 2 MB of whole lines):

1. :func:`~tollcli.readers.nmea.bulk_lines.split_block` frames every line and verifies the
   checksums of the plain ones with array operations;
2. :mod:`~tollcli.readers.nmea.bulk_sentences` decodes GGA, RMC, VTG, GSA, GSV, GST, GRS,
   GBS, GNS, GLL and ZDA in bulk; lines it cannot read plainly and other lines go through the reference reader's per-line classifier
   and converters, which also decide what is malformed;
3. epochs are cut where the time of day changes (as the reference assembler does),
   the last, possibly unfinished epoch is carried into the next block;
4. :mod:`~tollcli.readers.nmea.bulk_epochs` assembles the common epochs in bulk; an epoch
   with anything else is fed, sentence by sentence, to the reference
   :class:`~tollcli.readers.nmea.assembler.EpochAssembler`.

Steps 1–3 are the decoding stage (:meth:`BulkReader.decode`), step 4 and the counting of the lines the assembling
stage (:meth:`BulkReader.take`); ``tollcli epochs`` runs them on two threads a block apart.

The result is the reference reader's, table for table: ``tests/test_bulk_reader.py``
compares both on every gpsd log. Should the time stamps of a block ever fall outside
what the epoch cut assumes, the rest of the log is read by the reference path.

Why this file is long: the two stages hand each other one record (:class:`Decoded`) whose fields are read in one
place only if both stages live beside it — the decoding, the epoch cut, the counting and the assembly are one
block's life, and the stage boundary is the one thing a reader of this file must see whole.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tollcli.errors import DataError
from tollcli.readers.nmea import bulk_epochs, bulk_sentences
from tollcli.readers.nmea.assembler import EpochAssembler
from tollcli.readers.nmea.bulk_lines import (
    BlockLines,
    other_sentences,
    pack_address,
    reframe_glued,
    split_block,
    type_code,
    unpack_address,
)
from tollcli.readers.nmea.fields import time_of_day_s
from tollcli.readers.nmea.line_reader import (
    DISCARDED,
    HANDLED_TYPES,
    classify_line,
    feed_lines,
)

#: line kinds
BLANK, COMMENT, NOT_NMEA, NO_CHECKSUM, BAD_CHECKSUM, UNUSED, MALFORMED, DECODED = range(8)
_KIND = {"blank": BLANK, "comment": COMMENT, "not_nmea": NOT_NMEA, "no_checksum": NO_CHECKSUM,
         "bad_checksum": BAD_CHECKSUM, "unused": UNUSED}  # fmt: skip
_PROBLEM_NAME = {NOT_NMEA: "not_nmea", NO_CHECKSUM: "no_checksum", BAD_CHECKSUM: "bad_checksum", MALFORMED: "malformed"}
_TIMED_FIRST = {"GGA", "RMC", "GNS", "GST", "GRS", "GBS", "ZDA"}
_BULK = {pack_address("XX" + t) >> 16: t for t in bulk_epochs.SENTENCE_TYPES}
_DECODERS = {"GGA": bulk_sentences.gga, "RMC": bulk_sentences.rmc, "VTG": bulk_sentences.vtg,
             "GSA": bulk_sentences.gsa, "GSV": bulk_sentences.gsv, "GST": bulk_sentences.gst,
             "GLL": bulk_sentences.gll, "ZDA": bulk_sentences.zda, "GRS": bulk_sentences.grs,
             "GBS": bulk_sentences.gbs, "GNS": bulk_sentences.gns}  # fmt: skip
#: an epoch longer than this (bytes) is not waited for: the rest of the log goes the reference way
MAX_CARRY_BYTES = 16 << 20
SAME_TIME_S = 5e-4  # as the reference assembler


#: what the decoding stage hands the assembling stage (:class:`Decoded`'s ``route``)
BULK_ROUTE, REFERENCE_ROUTE, COUNTED_THEN_REFERENCE, END_ROUTE = range(4)


@dataclass
class Decoded:
    """A block as the decoding stage left it (:meth:`BulkReader.decode`), for :meth:`BulkReader.take`.

    ``route``: ``BULK_ROUTE`` (decoded: its first ``cut`` lines to count and its finished epochs, ``epochs``, to
    assemble), ``REFERENCE_ROUTE`` (``data`` to read the reference way, as the rest of the log),
    ``COUNTED_THEN_REFERENCE`` (the first ``cut`` lines counted, then ``data`` the reference way) or ``END_ROUTE``
    (the log ended with nothing carried)."""

    route: int
    data: bytes = b""
    final: bool = False
    first_line: int = 0
    bl: BlockLines | None = None
    kind: np.ndarray | None = None
    why: dict | None = None
    stype: np.ndarray | None = None
    cut: int = 0
    epochs: tuple | None = None  # _assemble's (dec, local, dec_tod, first_dec, n_done, slow, decoded, parsed)


class BulkReader:
    """Feed it blocks of whole lines with :meth:`feed`; it returns finished epochs as arrays.

    A block is read in two stages, which may run on two threads a block apart (each called in the blocks' order):
    :meth:`decode` frames and decodes the lines and cuts the epochs — it holds the unfinished last epoch (``carry``)
    and the count of lines before the block; :meth:`take` counts the lines into the statistics (raising there in
    strict mode) and assembles the finished epochs — it holds the epoch numbers and, once the log goes the reference
    way, the reference assembler. :meth:`feed` is the two at once."""

    def __init__(self, stats, strict: bool, name: str):
        self.stats = stats
        self.strict = strict
        self.name = name
        self.next_epoch = 0
        self.carry = b""
        self.reference: EpochAssembler | None = None  # set once the rest of the log goes the reference way
        self._handled = {pack_address("XX" + t) >> 16 for t in HANDLED_TYPES}
        self._line = stats.lines  # lines before the next block to decode
        self._referenced = False  # the decoding stage sends the rest of the log the reference way
        self.fast_epochs = 0  # epochs assembled in bulk (for tests and benchmarks)
        self.slow_epochs = 0

    # ------------------------------------------------------------------ public
    def feed(self, data: bytes, final: bool = False) -> dict[str, np.ndarray] | None:
        """Read one block (whole lines, no trailing line feed); the epochs it finished, or None."""
        return self.take(self.decode(data, final))

    def finish(self) -> dict[str, np.ndarray] | None:
        """End of the log: the last epoch."""
        return self.take(self.decode_end())

    def decode(self, data: bytes, final: bool = False) -> Decoded:
        """The decoding stage of a block (whole lines, no trailing line feed)."""
        if self.carry:
            data = self.carry + b"\n" + data
            self.carry = b""
        if self._referenced:
            return Decoded(REFERENCE_ROUTE, data, final)
        return self._bulk_decode(data, final)

    def decode_end(self) -> Decoded:
        """The decoding stage at the end of the log: the epoch it carried, as the last block."""
        if self.carry:
            data, self.carry = self.carry, b""
            return self.decode(data, final=True)
        return Decoded(END_ROUTE)

    def take(self, step: Decoded) -> dict[str, np.ndarray] | None:
        """The assembling stage of a decoded block: the epochs it finished, or None."""
        if step.route == END_ROUTE:
            if self.reference is not None:
                self.reference.finish()
                return self.reference.take()
            return None
        if step.route != REFERENCE_ROUTE:
            self._count(step.bl, step.kind, step.why, step.stype, step.cut, step.first_line)
        if step.route != BULK_ROUTE:
            return self._reference_feed(step.data, step.final)
        if step.epochs is None:
            return None
        return self._assemble(step.bl, step.first_line, *step.epochs)

    # ------------------------------------------------------------------ reference path
    def _reference_feed(self, data: bytes, final: bool) -> dict[str, np.ndarray]:
        if self.reference is None:
            self.reference = EpochAssembler()
            self.reference._next_epoch = self.next_epoch
        lines = data.decode("latin-1").replace("\r", "").split("\n") if data else []
        feed_lines(lines, self.reference, self.stats, self.strict, self.name)
        if final:
            self.reference.finish()
        self._count_slow(self.reference.n_ready)
        return self.reference.take()

    # ------------------------------------------------------------------ bulk path
    def _bulk_decode(self, data: bytes, final: bool) -> Decoded:
        bl = split_block(data)
        n = bl.start.size
        first_line = self._line
        kind = np.full(n, -1, np.int8)
        why: dict[int, str] = {}
        stype = np.full(n, None, dtype=object)  # None: not yet named (an empty address is a name)
        tod = np.full(n, np.nan)
        slow = np.zeros(n, bool)
        inert = np.zeros(n, bool)  # decoded, but changes no epoch (a VTG with mode 'N')
        parsed: dict[int, tuple[str, list[str]]] = {}
        for i in reframe_glued(bl).tolist():  # a sentence after binary bytes: read in bulk, the text before it counted
            why[i] = DISCARDED

        kind[bl.plain & ~bl.checksum_ok] = BAD_CHECKSUM
        for i in np.flatnonzero(bl.plain & ~bl.checksum_ok):
            why[int(i)] = f"bad checksum (*{int(bl.given[i]):02X} given, {int(bl.computed[i]):02X} computed)"
        good = bl.plain & bl.checksum_ok
        type3 = type_code(bl.address)
        proprietary = (bl.address & 0xFF) == ord("P")
        handled = good & ~proprietary & np.isin(type3, list(self._handled))
        kind[good & ~handled] = UNUSED

        decoded: dict[str, dict] = {}
        python_lines = list(self._other_sentences(bl, kind, why, stype))
        for code, t in _BULK.items():
            idx = np.flatnonzero(handled & (type3 == code))
            d = _DECODERS[t](bl, idx)
            d["line"] = idx
            ok = d["ok"]
            python_lines.extend(idx[~ok])
            d = bulk_epochs.subset(d, ok)
            kind[d["line"]] = DECODED
            stype[d["line"]] = t
            if "tod" in d:
                tod[d["line"]] = d["tod"]
            if "mode_n" in d:
                inert[d["line"][d["mode_n"]]] = True
            decoded[t] = d
        bulk_codes = np.array(list(_BULK), dtype=np.int64)
        python_lines.extend(np.flatnonzero(handled & ~np.isin(type3, bulk_codes)))
        self._per_line(bl, sorted(int(i) for i in python_lines), first_line, kind, why, stype, tod, slow, inert, parsed)

        # epochs: a new one where the time of day changes
        dec = np.flatnonzero((kind == DECODED) & ~inert)
        dec_tod = tod[dec]
        timed = ~np.isnan(dec_tod)
        cur_tod = _ffill(dec_tod)
        prev_tod = np.concatenate(([np.nan], cur_tod[:-1]))
        new = timed & ~np.isnan(prev_tod) & ~(np.abs(dec_tod - prev_tod) < SAME_TIME_S)
        local = np.cumsum(new)
        n_local = int(local[-1]) + 1 if dec.size else 0
        if n_local:
            first_dec = np.flatnonzero(np.concatenate(([True], local[1:] != local[:-1])))
            first_tod = _first_timed(local, dec_tod, n_local)
            spread = np.abs(dec_tod - first_tod[local])
            opener = first_tod[local[first_dec[1:]]]
            before = first_tod[local[first_dec[1:]] - 1]
            if np.any(spread[timed] >= SAME_TIME_S) or np.any(~(np.abs(opener - before) >= SAME_TIME_S)):
                self._referenced = True
                return Decoded(REFERENCE_ROUTE, data, final)  # from here on, line by line

        # the last epoch may go on in the next block
        cut = n
        n_done = n_local
        if not final and n_local:
            cut = int(dec[first_dec[-1]])
            n_done = n_local - 1
            self.carry = data[(bl.start if bl.line_start is None else bl.line_start)[cut] :]
            if len(self.carry) > MAX_CARRY_BYTES:  # no epoch end in sight: go line by line from here
                data, self.carry = self.carry, b""
                self._referenced = True
                return Decoded(COUNTED_THEN_REFERENCE, data, final, first_line, bl, kind, why, stype, cut)
        self._line = first_line + cut
        epochs = (dec, local, dec_tod, first_dec, n_done, slow, decoded, parsed) if n_done else None
        return Decoded(BULK_ROUTE, b"", final, first_line, bl, kind, why, stype, cut, epochs)

    @staticmethod
    def _other_sentences(bl: BlockLines, kind, why, stype) -> np.ndarray:
        """Classify the non-plain lines that are whole unused sentences (``$PSTI``, ``$GYOACC``); the rest, to read per line."""
        lines = np.flatnonzero(~bl.plain)
        framed, given, computed, names = other_sentences(bl, lines)
        ok = framed & (given == computed)
        kind[lines[ok]] = UNUSED
        stype[lines[ok]] = names[ok]
        bad = framed & ~ok
        kind[lines[bad]] = BAD_CHECKSUM
        for i, g, c in zip(lines[bad].tolist(), given[bad].tolist(), computed[bad].tolist()):
            why[i] = f"bad checksum (*{g:02X} given, {c:02X} computed)"
        return lines[~framed]

    def _count_slow(self, n: int) -> None:
        self.slow_epochs += n
        self.stats.per_line_epochs += n

    def _per_line(self, bl: BlockLines, lines, first_line, kind, why, stype, tod, slow, inert, parsed) -> None:
        """Classify and check lines one by one, as the reference reader does (the rare ones)."""
        scratch = EpochAssembler()
        for i in lines:
            k, reason, address, fields = classify_line(bl.text(i))
            if reason == DISCARDED:
                why[i] = reason  # counted by _count, the one place a line's statistics are added
                reason = ""
            if k != "sentence":
                kind[i] = _KIND[k]
                if reason:
                    why[i] = reason
                if k == "unused":
                    stype[i] = address  # the full address, for the unused-type counts
                continue
            t = address[2:]
            try:
                scratch.feed(address[:2], t, fields, first_line + i + 1)
            except (ValueError, IndexError, OverflowError) as exc:
                kind[i] = MALFORMED
                why[i] = f"malformed {address}: {exc}"
                continue
            kind[i] = DECODED
            stype[i] = t
            slow[i] = True
            parsed[i] = (address, fields)
            if t in _TIMED_FIRST:
                tod[i] = time_of_day_s(fields[0])
            elif t == "GLL" and len(fields) > 4:
                tod[i] = time_of_day_s(fields[4])
            elif t == "VTG" and len(fields) > 8 and fields[1] in ("T", "") and fields[8] == "N":
                inert[i] = True
            if scratch.n_ready > 1000:
                scratch = EpochAssembler()

    def _count(self, bl: BlockLines, kind, why, stype, cut: int, first_line: int) -> None:
        """Add the first ``cut`` lines to the statistics (and stop at the first problem when strict)."""
        stats = self.stats
        k = kind[:cut]
        counts = np.bincount(k, minlength=8)
        problems = np.flatnonzero((k == NOT_NMEA) | (k == NO_CHECKSUM) | (k == BAD_CHECKSUM) | (k == MALFORMED))
        if problems.size:
            i = int(problems[0])
            if self.strict:
                raise DataError(f"{self.name}:{first_line + i + 1}: {why[i]}")
            if not stats.first_problem:
                stats.first_problem = f"line {first_line + i + 1}: {why[i]}"
        stats.blank += int(counts[BLANK])
        stats.comments += int(counts[COMMENT])
        stats.not_nmea += int(counts[NOT_NMEA])
        stats.no_checksum += int(counts[NO_CHECKSUM])
        stats.bad_checksum += int(counts[BAD_CHECKSUM])
        stats.malformed += int(counts[MALFORMED])
        stats.unused += int(counts[UNUSED])
        stats.decoded += int(counts[DECODED])
        stats.sentences += int(counts[UNUSED] + counts[MALFORMED] + counts[DECODED])
        stats.discarded_text += sum(1 for i, w in why.items() if i < cut and w == DISCARDED and k[i] in (UNUSED, DECODED))
        unused = np.flatnonzero(k == UNUSED)
        if unused.size:
            names = stype[unused]
            unnamed = np.equal(names, None)
            if unnamed.any():  # plain lines: their packed five-character address
                codes, inverse = np.unique(bl.address[unused[unnamed]], return_inverse=True)
                names[unnamed] = np.array([unpack_address(int(c)) for c in codes], dtype=object)[inverse.ravel()]
            uniq, first, counts = np.unique(names.astype(str), return_index=True, return_counts=True)
            for j in np.argsort(first, kind="stable"):  # in first-seen order, as the reference reader's dict
                stats.unused_types[str(uniq[j])] = stats.unused_types.get(str(uniq[j]), 0) + int(counts[j])
        stats.lines = first_line + cut

    def _assemble(self, bl, first_line, dec, local, dec_tod, first_dec, n_done, slow, decoded, parsed):
        """Arrays of the ``n_done`` finished epochs: the common ones in bulk, the rest line by line."""
        in_done = local < n_done
        ep_tod = _first_timed(local, dec_tod, n_done + 1)[:n_done]
        keep_epoch = ~np.isnan(ep_tod)  # an epoch without a time is not one (the reference drops it too)
        ep_global = np.full(n_done, -1, np.int64)
        ep_global[keep_epoch] = self.next_epoch + np.arange(int(keep_epoch.sum()))
        self.next_epoch += int(keep_epoch.sum())
        ep_line = first_line + dec[first_dec[:n_done]] + 1
        is_slow = np.zeros(n_done, bool)
        if slow.any():
            is_slow[local[in_done][slow[dec[in_done]]]] = True

        # the bulk-decoded rows of every type, by epoch
        line_epoch = np.full(bl.start.size, -1, np.int64)
        line_epoch[dec[in_done]] = local[in_done]
        rows = {}
        for t, d in decoded.items():
            e = line_epoch[d["line"]]
            d = bulk_epochs.subset(d, e >= 0)
            d["e"] = line_epoch[d["line"]]
            d["order"] = d["line"]
            rows[t] = d
        is_slow |= bulk_epochs.unsupported_epochs(n_done, rows)
        fast = keep_epoch & ~is_slow
        position = np.cumsum(fast) - 1
        for t, d in rows.items():
            d = bulk_epochs.subset(d, fast[d["e"]])
            d["e"] = position[d["e"]]
            rows[t] = d
        fast_ids = np.flatnonzero(fast)
        parts = [bulk_epochs.assemble(ep_global[fast_ids], ep_tod[fast_ids], ep_line[fast_ids], rows)]
        self.fast_epochs += fast_ids.size
        slow_ids = np.flatnonzero(keep_epoch & is_slow)
        if slow_ids.size:
            parts.append(self._reference_epochs(bl, first_line, dec, local, slow_ids, ep_global, parsed))
            self._count_slow(slow_ids.size)
        return merge_arrays(parts)

    def _reference_epochs(self, bl, first_line, dec, local, epoch_ids, ep_global, parsed):
        """The given epochs assembled sentence by sentence by the reference assembler."""
        asm = EpochAssembler()
        wanted = np.zeros(int(local.max()) + 1, bool)
        wanted[epoch_ids] = True
        current = -1
        for i, ep in zip(dec[wanted[local]].tolist(), local[wanted[local]].tolist()):
            if ep != current:
                asm.finish()  # closes the previous epoch
                asm._next_epoch = int(ep_global[ep])
                current = ep
            if i in parsed:
                address, fields = parsed[i]
            else:
                _, _, address, fields = classify_line(bl.text(i))
            asm.feed(address[:2], address[2:], fields, first_line + i + 1)
        asm.finish()
        return asm.take()


def _ffill(values: np.ndarray) -> np.ndarray:
    """NaNs replaced by the last value before them (NaN at the start)."""
    idx = np.where(~np.isnan(values), np.arange(values.size), -1)
    np.maximum.accumulate(idx, out=idx)
    out = np.where(idx >= 0, values[np.maximum(idx, 0)], np.nan)
    return out


def _first_timed(local: np.ndarray, tod: np.ndarray, n: int) -> np.ndarray:
    """Per epoch, the time of its first timed sentence (NaN when none)."""
    out = np.full(n, np.nan)
    timed = ~np.isnan(tod)
    e = local[timed]
    if e.size:  # ``local`` never decreases: an epoch's first timed sentence is where ``e`` changes
        first = np.flatnonzero(np.r_[True, e[1:] != e[:-1]])
        uniq = e[first]
        keep = uniq < n
        out[uniq[keep]] = tod[timed][first[keep]]
    return out


def merge_arrays(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Concatenate epoch arrays from both paths, in epoch order."""
    parts = [p for p in parts if p["epoch"].size or p["sat_epoch"].size]
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return EpochAssembler().take()
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    if np.all(out["epoch"][1:] >= out["epoch"][:-1]) and np.all(out["sat_epoch"][1:] >= out["sat_epoch"][:-1]):
        return out  # already in epoch order (the usual case: parts in reading order)
    order = np.argsort(out["epoch"], kind="stable")
    sat_order = np.argsort(out["sat_epoch"], kind="stable")
    return {k: (v[sat_order] if k.startswith("sat_") else v[order]) for k, v in out.items()}
