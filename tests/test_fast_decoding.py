"""The array paths that replaced per-byte Python loops decode exactly what the loops did: UBX framing with
block checksums (against a frame-by-frame reference), and the Reed–Solomon erasure fast path (against
``reedsolo``, errors included, where the fast path must hand over)."""

from __future__ import annotations

import io
import random

import numpy as np
import pytest

from tollcli.errors import DataError
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.ubx_frames import SYNC, block_checksums, checksum, frame, iter_frames


def _reference_frames(data: bytes) -> tuple[list, tuple]:
    """Frame by frame, byte by byte: the reader's rules written plainly (sync pair, length ≤ 8192, checksum; a bad
    checksum, an impossible length or a frame the data ends inside makes the search start two bytes on)."""
    out, at, number, bad, cut = [], 0, 0, 0, 0
    while True:
        at = data.find(SYNC, at)
        if at < 0:
            break
        if len(data) < at + 6:
            number, cut, at = number + 1, cut + 1, at + 2
            continue
        length = data[at + 4] | (data[at + 5] << 8)
        end = at + 8 + length
        if length > 8192:
            at += 2
            continue
        number += 1
        if len(data) < end:
            cut, at = cut + 1, at + 2
            continue
        if checksum(data[at + 2 : end - 2]) != data[end - 2 : end]:
            bad += 1
            at += 2
            continue
        out.append((data[at + 2], data[at + 3], data[at + 6 : end - 2], number))
        at = end
    return out, (number, number - bad - cut, bad, cut)


def _frames(data: bytes, block_bytes: int) -> tuple[list, tuple]:
    stats = ReadStats()
    got = list(iter_frames(io.BytesIO(data), "log", stats, False, block_bytes=block_bytes))
    return got, (stats.lines, stats.sentences, stats.bad_checksum, stats.malformed)


def _log(rng: random.Random, n: int) -> bytes:
    parts = []
    for _ in range(n):
        parts.append(frame(rng.randrange(256), rng.randrange(256), bytes(rng.randrange(256) for _ in range(rng.randrange(0, 90)))))
        if rng.random() < 0.2:
            parts.append(b"$GPGGA,noise*00\r\n" + SYNC * rng.randrange(3))
    return b"".join(parts)


def test_block_checksums_are_the_fletcher_checksums():
    rng = random.Random(3)
    buf = bytes(rng.randrange(256) for _ in range(5000))
    starts = np.array(sorted(rng.sample(range(4000), 50)), np.int64)
    ends = starts + np.array([rng.randrange(0, 900) for _ in starts], np.int64)
    got = block_checksums(buf, starts, ends)
    assert got.tolist() == [int.from_bytes(checksum(buf[s:e]), "big") for s, e in zip(starts, ends)]


@pytest.mark.parametrize("seed", range(12))
def test_framing_matches_the_frame_by_frame_reference_on_damaged_logs(seed):
    rng = random.Random(seed)
    data = bytearray(_log(rng, 400))
    for _ in range(rng.randrange(20, 60)):  # flipped bytes: bad checksums, false lengths, false sync pairs
        data[rng.randrange(len(data))] = rng.randrange(256)
    data = bytes(data[: len(data) - rng.randrange(0, 30)])  # and a cut last frame
    want = _reference_frames(data)
    assert want[1][2] > 0 and len(want[0]) > 200  # damaged, and mostly readable
    for block_bytes in (1, 7, 64, 1000, 1 << 20):
        assert _frames(data, block_bytes) == want


def test_a_false_sync_pair_whose_length_runs_past_the_end_hides_no_frame():
    """Text before the last frames holds a sync pair whose "length" runs past the end of the file: it is counted as a
    frame the file ends inside, and the real frames after it are read (they were lost behind it)."""
    good = [frame(0x01, 0x07, bytes([k]) * 92) for k in range(3)]
    data = good[0] + b"$GPTXT,noise \xb5\x62\x01\x02\xff\x1f*00\r\n" + good[1] + good[2]
    got, counts = _frames(data, 1 << 20)
    assert [g[3] for g in got] == [1, 3, 4] and [g[2][0] for g in got] == [0, 1, 2] and counts == (4, 3, 0, 1)
    assert _frames(data, 5) == (got, counts) == _reference_frames(data)


def test_strict_names_the_first_bad_frame():
    good = frame(0x01, 0x07, bytes(92))
    bad = bytearray(frame(0x01, 0x35, bytes(8)))
    bad[-1] ^= 0xFF
    with pytest.raises(DataError, match=r"log: UBX message 2 \(class 0x01 id 0x35\): bad checksum"):
        list(iter_frames(io.BytesIO(good + bytes(bad) + good), "log", ReadStats(), True))


def test_reed_solomon_fast_path_agrees_with_reedsolo_and_hands_over_on_errors():
    reedsolo = pytest.importorskip("reedsolo")
    from tollcli.gnss.osnma.reed_solomon import erasure_decode

    codec = reedsolo.RSCodec(60, nsize=255, fcr=1, prim=0x11D)
    rng = random.Random(5)
    fast = handed_over = 0
    for trial in range(150):
        word = bytes(codec.encode(bytes(rng.randrange(256) for _ in range(58))))
        erased = rng.sample(range(118), rng.randint(40, 60))
        received = bytearray(word)
        for p in erased:
            received[p] = rng.randrange(256)
        errors = trial % 3  # 0, 1 or 2 symbols received wrong outside the erasures
        for q in rng.sample([i for i in range(118) if i not in erased], errors):
            received[q] ^= rng.randrange(1, 256)
        got = erasure_decode(received, erased)
        if errors and len(erased) + errors <= 60:
            # a word agreeing with every symbol received would lie within 60 < 61 (the distance) of the sent one
            assert got is None  # so there is none: reedsolo must decode
            handed_over += 1
        elif got is not None:  # no error, or too little redundancy left to see one: the word reedsolo finds too
            assert got == bytes(codec.decode(bytearray(received), erase_pos=erased)[1])
            assert got == word or errors
            fast += 1
        else:
            assert errors  # an error-free word always takes the fast path
            handed_over += 1
    assert fast > 50 and handed_over > 80


def test_too_many_erasures_hand_over():
    from tollcli.gnss.osnma.reed_solomon import erasure_decode

    assert erasure_decode(bytes(118), list(range(61))) is None
    assert erasure_decode(bytes(118), list(range(60))) == bytes(118)  # the zero word fits

