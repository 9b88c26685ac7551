"""A chunk's blocks joined: the epoch arrays at once, the satellite arrays (``sat_*``) when first looked up.

A chunk of the NMEA reader is the arrays of ten or so blocks, in reading order. Its epoch arrays are small (about 240
bytes an epoch); its satellite arrays are about 47 bytes a satellite-epoch, some 60 MB for a 20 000-epoch chunk of a
multi-constellation receiver. ``tollcli epochs`` without ``--satellites`` never reads them: joining them would be
about a tenth of a second of copying on the thread that assembles the epochs, for nothing. :func:`join_blocks` joins
the epoch arrays and leaves the satellite arrays to the first reader of any of them.

The result is what :func:`~tollcli.readers.nmea.bulk_reader.merge_arrays` gives, array for array
(``tests/test_bulk_reader.py``): where the blocks are in epoch order (each block's satellite rows sorted by epoch, and
no block's rows before the last one's), merging is joining; anything else is merged at once, as before.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Mapping

import numpy as np

from tollcli.readers.nmea.bulk_reader import merge_arrays

SATELLITE_PREFIX = "sat_"


class JoinedArrays(Mapping):
    """The arrays of blocks in epoch order: the epoch arrays joined, the satellite arrays joined on first lookup.

    ``satellite_rows`` is their row count, known without joining them. Looked up from several threads at once, the
    satellite arrays are still joined once, and every lookup waits for them."""

    def __init__(self, epochs: dict[str, np.ndarray], blocks: list[dict[str, np.ndarray]], names: list[str]):
        self._arrays = epochs
        self._blocks: list[dict[str, np.ndarray]] | None = blocks
        self._names = names
        self.satellite_rows = sum(b["sat_epoch"].size for b in blocks)
        self._joining = threading.Lock()

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._arrays and name.startswith(SATELLITE_PREFIX):
            with self._joining:
                if self._blocks is not None:
                    for key in self._blocks[0]:
                        if key.startswith(SATELLITE_PREFIX):
                            self._arrays[key] = np.concatenate([b[key] for b in self._blocks])
                    self._blocks = None  # the blocks let go once joined
        return self._arrays[name]

    def __setitem__(self, name: str, values: np.ndarray) -> None:
        if name not in self._arrays and name not in self._names:
            self._names.append(name)
        self._arrays[name] = values

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


def join_blocks(blocks: list[dict[str, np.ndarray]]) -> Mapping[str, np.ndarray]:
    """The blocks' arrays as one chunk: a :class:`JoinedArrays` where they are in epoch order, else
    :func:`~tollcli.readers.nmea.bulk_reader.merge_arrays` of them (which sorts them)."""
    blocks = [b for b in blocks if b["epoch"].size or b["sat_epoch"].size]
    if len(blocks) < 2:
        return merge_arrays(blocks)
    epochs = {k: np.concatenate([b[k] for b in blocks]) for k in blocks[0] if not k.startswith(SATELLITE_PREFIX)}
    if not _in_epoch_order(epochs["epoch"], [b["sat_epoch"] for b in blocks]):
        return merge_arrays(blocks)
    return JoinedArrays(epochs, blocks, list(blocks[0]))


def satellite_rows(arrays: Mapping[str, np.ndarray]) -> int:
    """The satellite rows of a chunk's arrays, without joining them."""
    return arrays.satellite_rows if isinstance(arrays, JoinedArrays) else arrays["sat_epoch"].size


def _in_epoch_order(epoch: np.ndarray, sat_epochs: list[np.ndarray]) -> bool:
    """Whether the joined epochs, and the blocks' satellite epochs joined, never decrease."""
    if np.any(epoch[1:] < epoch[:-1]):
        return False
    last = None
    for s in sat_epochs:
        if s.size == 0:
            continue
        if np.any(s[1:] < s[:-1]) or (last is not None and s[0] < last):
            return False
        last = s[-1]
    return True
