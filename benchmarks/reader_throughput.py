"""NMEA reader throughput against plain pynmea2, and peak memory against log size.

Real patterns (the figures that count): each receiver pattern of
:mod:`real_patterns` (a real gpsd log's sentence sequence: u-blox, Quectel, SiRF,
MediaTek, SkyTraq, ST, Unicore, Telit) is replayed, re-timed, into a log of at least
``--pattern-lines`` lines and read by the bulk reader and by ``pynmea2.parse``; per pattern:
lines/s, the ratio to pynmea2 in the same run, and the share of epochs read line by line.

Speed: the same synthetic multi-constellation log (RMC, VTG, GGA, 2×GSA, 3×GSV,
GST per epoch) is read by ``tollcli.readers.nmea.iter_nmea_tables`` (full decoding into
epoch and satellite tables) with the bulk path (the default, with its compiled
kernels), the bulk path with its numpy kernels only (an install without a C
compiler), and the per-line reference path, and by ``pynmea2.parse`` on every line (sentence objects only, no
tables: the baseline). All read the file from disk; best of ``--repeat`` runs, in
turn, in one process.

Memory: each log size is read in a fresh subprocess that discards the chunks;
the peak resident set size (``ru_maxrss``) is reported, with the ratio of the
largest log's peak to the smallest's (1.0 = flat in log length).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tollcli.readers.nmea import ReadStats, compose, iter_nmea_tables, kernels

BYTES_PER_EPOCH = 562  # of compose.straight_drive, measured


def write_log(path: Path, target_bytes: int) -> int:
    """A synthetic drive of about ``target_bytes``; returns the number of lines."""
    n_epochs = max(1, target_bytes // BYTES_PER_EPOCH)
    lines = 0
    with open(path, "w", encoding="ascii") as fh:
        batch: list[str] = []
        for line in compose.straight_drive(n_epochs):
            batch.append(line)
            if len(batch) >= 100_000:
                fh.write("\n".join(batch) + "\n")
                lines += len(batch)
                batch.clear()
        fh.write("\n".join(batch) + "\n")
        lines += len(batch)
    return lines


def ours(path: Path, engine: str = "bulk", compiled: bool = True) -> float:
    saved = kernels.compiled
    if not compiled:
        kernels.compiled = None  # the numpy kernels: what an install without a C compiler runs
    try:
        start = time.perf_counter()
        stats = ReadStats()
        for _ in iter_nmea_tables(path, stats=stats, engine=engine):
            pass
        return time.perf_counter() - start
    finally:
        kernels.compiled = saved


def plain_pynmea2(path: Path) -> float:
    import pynmea2

    start = time.perf_counter()
    with open(path, encoding="latin-1") as fh:
        for line in fh:
            try:
                pynmea2.parse(line.rstrip("\n"))
            except pynmea2.ParseError:  # real receivers write sentences pynmea2 refuses (counted in its time)
                pass
    return time.perf_counter() - start


def peak_rss_mb(path: Path) -> float:
    """Peak RSS of a fresh process that reads ``path`` through the chunked reader."""
    code = (
        "import resource, sys\n"
        "from tollcli.readers.nmea import iter_nmea_tables\n"
        "n = 0\n"
        "for chunk in iter_nmea_tables(sys.argv[1]):\n"
        "    n += len(chunk.epochs)\n"
        "print(n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    epochs, kib = out.stdout.split()
    return int(kib) / 1024.0


def patterns(tmp: str, min_lines: int, repeat: int) -> None:
    """Per real receiver pattern: bulk reader lines/s, ratio to pynmea2, per-line share."""
    import real_patterns

    if not real_patterns.DATA.is_dir():
        print(f"real patterns: {real_patterns.DATA} not found (the shared data); skipped")
        return
    print(f"{'pattern (gpsd log)':48s} {'lines':>9s} {'bulk lines/s':>13s} {'pynmea2 l/s':>12s} {'ratio':>6s} {'per-line':>8s}")
    for name, log_name in real_patterns.PATTERNS.items():
        path = Path(tmp) / "pattern.nmea"
        n_lines = real_patterns.replay(real_patterns.DATA / log_name, path, min_lines)
        stats = ReadStats()
        for _ in iter_nmea_tables(path, stats=stats):
            pass
        t_ours = min(ours(path) for _ in range(repeat))
        t_base = min(plain_pynmea2(path) for _ in range(repeat))
        share = stats.per_line_epochs / max(stats.epochs, 1)
        print(f"{name + ' (' + log_name + ')':48s} {n_lines:9,d} {n_lines / t_ours:13,.0f} {n_lines / t_base:12,.0f} "
              f"{t_base / t_ours:6.2f} {share:8.2%}")
        path.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed-mb", type=float, default=20.0, help="size of the speed-test log, MB")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--memory-gb", type=float, nargs="*", default=[0.1, 1.0], help="log sizes for the memory test, GB")
    parser.add_argument("--no-memory", action="store_true")
    parser.add_argument("--pattern-lines", type=int, default=500_000, help="lines per replayed real pattern (0: skip them)")
    parser.add_argument("--workdir", default=None, help="where to write the logs (default: a temporary folder)")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        if args.pattern_lines:
            patterns(tmp, args.pattern_lines, args.repeat)
        log = Path(tmp) / "speed.nmea"
        n_lines = write_log(log, int(args.speed_mb * 1e6))
        ours(log)  # warm the look-up tables and the page cache
        times = {"bulk": [], "numpy": [], "reference": [], "pynmea2": []}
        for _ in range(args.repeat):
            times["bulk"].append(ours(log))
            times["numpy"].append(ours(log, compiled=False))
            times["reference"].append(ours(log, "reference"))
            times["pynmea2"].append(plain_pynmea2(log))
        t_ours, t_ref, t_base = (min(times[k]) for k in ("bulk", "reference", "pynmea2"))
        print(f"log: {n_lines} lines, {os.path.getsize(log) / 1e6:.1f} MB (synthetic, GPS+Galileo, 9 sentences/epoch)")
        t_numpy = min(times["numpy"])
        print(f"tollcli bulk reader (epoch+satellite tables):      {n_lines / t_ours:12,.0f} lines/s"
              f"  ({'compiled kernels' if kernels.compiled is not None else 'NOT COMPILED: numpy kernels'})")
        print(f"tollcli bulk reader, numpy kernels only:           {n_lines / t_numpy:12,.0f} lines/s")
        print(f"tollcli reference reader (per line, same tables):  {n_lines / t_ref:12,.0f} lines/s")
        print(f"pynmea2.parse per line (baseline, no tables):      {n_lines / t_base:12,.0f} lines/s")
        print(f"ratio bulk / pynmea2:                              {t_base / t_ours:12.2f}")
        print(f"ratio bulk / reference:                            {t_ref / t_ours:12.2f}")
        print(f"ratio numpy-kernel bulk / pynmea2:                 {t_base / t_numpy:12.2f}")
        if args.no_memory:
            return
        results = []
        for gb in sorted(args.memory_gb):
            path = Path(tmp) / f"mem-{gb}.nmea"
            lines = write_log(path, int(gb * 1e9))
            mb = peak_rss_mb(path)
            results.append((gb, lines, mb))
            print(f"log {os.path.getsize(path) / 1e9:6.2f} GB ({lines:,} lines): peak RSS {mb:8.1f} MB")
            path.unlink()
        if len(results) > 1:
            print(f"peak RSS ratio, {results[-1][0]} GB / {results[0][0]} GB log: {results[-1][2] / results[0][2]:.2f}")


if __name__ == "__main__":
    main()
