"""A chunk's blocks joined (satellite arrays on first lookup) equal the blocks merged, in order or not."""

from __future__ import annotations

import numpy as np
import pytest

from tollcli.readers.nmea.bulk_reader import merge_arrays
from tollcli.readers.nmea.joined_blocks import JoinedArrays, join_blocks, satellite_rows


def _block(rng, epochs: np.ndarray, sats_per_epoch: int) -> dict[str, np.ndarray]:
    sat_epoch = np.repeat(epochs, rng.integers(0, sats_per_epoch + 1, epochs.size))
    return {
        "epoch": epochs.astype(np.int64),
        "tod_s": rng.random(epochs.size),
        "sat_epoch": sat_epoch.astype(np.int64),
        "sat_cn0_dbhz": rng.random(sat_epoch.size),
        "sat_used": rng.random(sat_epoch.size) < 0.5,
    }


def _blocks(rng, n_blocks: int, shuffled: bool) -> list[dict[str, np.ndarray]]:
    sizes = rng.integers(0, 6, n_blocks)
    starts = np.concatenate([[0], np.cumsum(sizes)])
    blocks = [_block(rng, np.arange(starts[i], starts[i + 1]), 4) for i in range(n_blocks)]
    if shuffled:
        rng.shuffle(blocks)
    return blocks


def _assert_equal(joined, merged) -> None:
    assert list(joined) == list(merged)
    for key in merged:
        assert joined[key].dtype == merged[key].dtype and np.array_equal(joined[key], merged[key]), key


@pytest.mark.parametrize("seed", range(40))
def test_joined_equals_merged(seed):
    rng = np.random.default_rng(seed)
    blocks = _blocks(rng, int(rng.integers(0, 7)), shuffled=bool(seed % 2))
    expected = merge_arrays([dict(b) for b in blocks])
    joined = join_blocks(blocks)
    assert satellite_rows(joined) == expected["sat_epoch"].size
    _assert_equal(joined, expected)


def test_blocks_in_order_are_joined_their_satellites_when_first_looked_up():
    rng = np.random.default_rng(7)
    blocks = [_block(rng, np.arange(10 * i, 10 * i + 10), 3) for i in range(3)]
    joined = join_blocks(blocks)
    assert isinstance(joined, JoinedArrays)
    assert joined["epoch"].tolist() == list(range(30))
    blocks[1]["sat_cn0_dbhz"][:] = -1.0  # changed after joining, before any satellite array was looked up
    assert (joined["sat_cn0_dbhz"] == -1.0).sum() == blocks[1]["sat_epoch"].size > 0
    joined["date_jump_days"] = np.zeros(30)  # the reader adds a column to the chunk it dates
    assert list(joined)[-1] == "date_jump_days" and len(joined) == 6


def test_a_block_whose_satellites_go_back_is_merged_at_once():
    rng = np.random.default_rng(3)
    first, second = _block(rng, np.arange(0, 5), 3), _block(rng, np.arange(5, 10), 3)
    first["sat_epoch"] = np.array([0, 4, 4])
    first["sat_cn0_dbhz"], first["sat_used"] = rng.random(3), np.ones(3, bool)
    second["sat_epoch"][:] = 0  # satellite rows of an earlier epoch in a later block
    assert second["sat_epoch"].size
    merged = merge_arrays([dict(first), dict(second)])
    joined = join_blocks([first, second])
    assert not isinstance(joined, JoinedArrays)
    _assert_equal(joined, merged)


def test_satellites_looked_up_from_two_threads_at_once_are_joined_once(monkeypatch):
    import threading

    from tollcli.readers.nmea import joined_blocks

    rng = np.random.default_rng(11)
    blocks = [_block(rng, np.arange(10 * i, 10 * i + 10), 3) for i in range(3)]
    expected = merge_arrays([dict(b) for b in blocks])
    joined = join_blocks(blocks)
    calls, started = [], threading.Barrier(2)
    real = np.concatenate

    def slow_concatenate(parts):  # the first joiner still joining when the second looks
        calls.append(1)
        threading.Event().wait(0.02)
        return real(parts)

    monkeypatch.setattr(joined_blocks.np, "concatenate", slow_concatenate)
    found, errors = {}, []

    def look(name):
        started.wait()
        try:
            found[name] = joined[name]
        except Exception as exc:  # noqa: BLE001 - what the other thread saw
            errors.append(exc)

    threads = [threading.Thread(target=look, args=(n,)) for n in ("sat_cn0_dbhz", "sat_used")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(calls) == 3  # the three satellite arrays, joined once
    for name in found:
        assert np.array_equal(found[name], expected[name])
