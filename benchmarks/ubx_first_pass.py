"""What a u-blox log's first pass keeps as the log grows: its navigation subframes, RAWX heads and NAV-PVT rows sifted to
those the orbits need (``read_ubx(subframes_kept=sfrbx_kept, times_kept=times_kept)``, as ``tollcli integrity``/
``process`` read a RAWX log) against all of them, in the same run.

    python benchmarks/ubx_first_pass.py [--copies 1 4 8]

The log: the real OSNMA recording (``../shared/data/osnma/ublox/current_config.ubx``: 80 min, 28 085 Galileo I/NAV
pages, 4 753 NAV-PVT) written 1, 4 and 8 times over into one file (the same pages again: a stand-in for a longer
recording; there is no longer real one). Printed per length and way, each read once timed and once under
``tracemalloc``: the subframe rows held at the end and their bytes, the NAV-PVT rows and their bytes, what the first
pass keeps in all (the memory still allocated after it, its tables) and its peak while reading, the seconds the read
and the decoding of the ephemerides take, and whether the ephemerides are the same both ways; then the ratios of the
longest to the shortest (1.0: flat). The second pass keeps nothing of the first: it reads each block's NAV-PVT beside
its RAWX (``iter_rawx(with_pvt=True)``). ≈ 40 s.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tollcli.gnss.ubx_measurements import sfrbx_ephemerides, sfrbx_kept, times_kept  # noqa: E402
from tollcli.readers.ubx import read_ubx  # noqa: E402

RECORDING = ROOT.parent / "shared" / "data" / "osnma" / "ublox" / "current_config.ubx"


def first_pass(path: str, sifted: bool) -> dict:
    """One first pass of ``path`` (sifted or not) timed, another under tracemalloc, and the ephemerides it decodes to."""
    kept_by = {"subframes_kept": sfrbx_kept, "times_kept": times_kept} if sifted else {}
    t0 = time.perf_counter()
    read = read_ubx(path, measurements=False, **kept_by)
    t_read = time.perf_counter() - t0
    del read
    tracemalloc.start()
    read = read_ubx(path, measurements=False, **kept_by)
    kept, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    t0 = time.perf_counter()
    eph = sfrbx_ephemerides(read)
    return {"rows": len(read.sfrbx), "subframes_mb": read.sfrbx.memory_usage(deep=True).sum() / 1e6,
            "pvt_mb": read.pvt.memory_usage(deep=True).sum() / 1e6, "kept_mb": kept / 1e6, "peak_mb": peak / 1e6,
            "read_s": t_read, "decode_s": time.perf_counter() - t0, "eph": eph, "pvt_rows": len(read.pvt)}  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[1, 4, 8], help="the recording written this many times over")
    args = parser.parse_args()
    if not RECORDING.exists():
        print(f"{RECORDING} not found", file=sys.stderr)
        return 1
    data = RECORDING.read_bytes()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in args.copies:
            path = os.path.join(tmp, f"recording-x{k}.ubx")
            with open(path, "wb") as out:
                out.write(data * k)
            every, sifted = first_pass(path, False), first_pass(path, True)
            rows[k] = (every, sifted)
            same = every["eph"].equals(sifted["eph"])
            for name, r in (("all subframes", every), ("sifted", sifted)):
                print(f"{k:2d}× ({80 * k:4d} min) {name:13s}: {r['rows']:7d} subframes {r['subframes_mb']:6.2f} MB, {r['pvt_rows']:6d} NAV-PVT "
                      f"{r['pvt_mb']:5.2f} MB; kept {r['kept_mb']:6.2f} MB, peak {r['peak_mb']:6.1f} MB; read {r['read_s']:.2f} s, "
                      f"ephemerides {r['decode_s']:.2f} s ({len(r['eph'])}{', the same' if name == 'sifted' and same else ''})")  # fmt: skip
            if not same:
                print("  THE EPHEMERIDES DIFFER")
    lo, hi = min(rows), max(rows)
    for i, name in enumerate(("all subframes", "sifted")):
        a, b = rows[lo][i], rows[hi][i]
        print(f"{hi}× / {lo}×, {name}: subframes {b['subframes_mb'] / a['subframes_mb']:.2f}, kept {b['kept_mb'] / a['kept_mb']:.2f}, "
              f"peak {b['peak_mb'] / a['peak_mb']:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
