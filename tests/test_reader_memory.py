"""Memory of the chunked reader does not grow with log length (tracemalloc, not timing)."""

from __future__ import annotations

import tracemalloc

from tollcli.readers.nmea import compose, iter_nmea_tables


def _peak_bytes(path, epochs_per_chunk: int) -> tuple[int, int]:
    tracemalloc.start()
    try:
        n = 0
        for chunk in iter_nmea_tables(path, chunk_epochs=epochs_per_chunk, block_bytes=64 * 1024):
            n += len(chunk.epochs)
        return n, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_peak_memory_is_flat_in_log_length(tmp_path):
    short, long = tmp_path / "short.nmea", tmp_path / "long.nmea"
    short.write_text("\n".join(compose.straight_drive(1_000)) + "\n")
    long.write_text("\n".join(compose.straight_drive(4_000)) + "\n")
    n_short, peak_short = _peak_bytes(short, 250)
    n_long, peak_long = _peak_bytes(long, 250)
    assert (n_short, n_long) == (1_000, 4_000)
    # four times the log, the same peak (a reader holding the log would need ~4x)
    assert peak_long < 1.3 * peak_short, (peak_short, peak_long)
