"""Read ahead: an iterator's next items made on a second thread while the caller works on the current one.

>>> with read_ahead(iter(range(3))) as items:
...     list(items)
[0, 1, 2]

The items come in their order, each once, and an exception the iterator raises is raised to the caller at the
place of the item it stopped at — after every item before it was handed over — so what the caller writes is what
it would write without reading ahead (the invoices are byte-identical, ``tests/test_prefetch.py``). At most
``depth`` items are made or waiting beyond the one the caller holds (the next is made only once there is room for
it): memory stays two chunks', not the log's. Leaving the
``with`` block, by its end, an error of the caller's or Ctrl-C, stops the thread at its next item and waits for
it, so nothing reads a log that is being closed. A thread that finished (the iterator ran out or raised) hands
over its last word without waiting for room, so it ends at once even when nobody takes it.

What it buys: the NMEA reader's compiled kernels and numpy release the interpreter lock, so the next chunk is read
while this one's integrity checks run (``benchmarks/process_throughput.py`` gives both, with ``TOLLCLI_READ_AHEAD=0``).
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
from collections.abc import Iterator
from typing import TypeVar

T = TypeVar("T")

#: the environment variable that turns reading ahead off (``0``): one thread, for measuring what it buys
ENVIRONMENT = "TOLLCLI_READ_AHEAD"
#: the name of the reading thread
THREAD_NAME = "tollcli-read-ahead"

_DONE = object()


def read_ahead_on() -> bool:
    """Whether to read ahead (not when ``TOLLCLI_READ_AHEAD=0``)."""
    return os.environ.get(ENVIRONMENT, "1").strip() != "0"


@contextlib.contextmanager
def read_ahead(items: Iterator[T], depth: int = 1) -> Iterator[Iterator[T]]:
    """``items`` in order, produced on a second thread up to ``depth`` ahead of the caller (see the module); the
    items themselves when reading ahead is off (:func:`read_ahead_on`)."""
    if not read_ahead_on():
        yield items
        return
    reader = _Reader(items, depth)
    try:
        yield reader.items()
    finally:
        reader.stop()


class _Reader:
    def __init__(self, items: Iterator[T], depth: int):
        self._source = items
        self._ready: queue.SimpleQueue = queue.SimpleQueue()
        self._room = threading.Semaphore(depth)
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._produce, name=THREAD_NAME, daemon=True)
        self._thread.start()

    def _produce(self) -> None:
        items = iter(self._source)
        while True:
            while not self._room.acquire(timeout=0.05):  # room first, then the next item: no item waits for room
                if self._stopping.is_set():
                    return
            if self._stopping.is_set():
                return
            try:
                item = next(items)
            except StopIteration:
                self._ready.put((_DONE, None))
                return
            except BaseException as exc:  # noqa: BLE001 - handed to the caller, raised there
                self._ready.put((_DONE, exc))
                return
            self._ready.put((item, None))

    def items(self) -> Iterator[T]:
        while True:
            item, exc = self._ready.get()
            if item is _DONE:
                if exc is not None:
                    raise exc
                return
            self._room.release()
            yield item

    def stop(self) -> None:
        """Stop the thread at its next item, wait for it, and close the source (its ``finally`` blocks run here)."""
        self._stopping.set()
        self._thread.join()
        close = getattr(self._source, "close", None)
        if close is not None:
            close()
