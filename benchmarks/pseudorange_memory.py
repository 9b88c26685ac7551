"""What a pseudorange log costs `tollcli integrity` as it grows: seconds and peak memory on the first quarter of a long
simulated city drive, on the whole of it, and on a drive twice as long, in the same run.

    python benchmarks/pseudorange_memory.py [--epochs 40000] [--longer 80000]

The drive is ``tollcli simulate --nlos --odometry --duration 8000 --rate 5 --seed 11`` (40 000 epochs at 5 Hz, written
once into ``benchmarks/integrity_truth/sim/city-long``, ≈ 80 s), as libRSF text (pseudoranges and odometry) and as a
GSDC derived CSV; the longer one the same with ``--duration 16000`` (``sim/city-80000``, ≈ 3 min once). Each is cut
to its first quarter (whole lines, the same epochs) and run with the whole and the longer drive. The ratios of the
peak RSS say how memory grows with the log (4.0 whole / quarter: in proportion; 1.0: flat). Both formats are read in
blocks and placed segment by segment (``tollcli/job/pseudorange_segments.py``: cores of 8 192 epochs and at least
30 min, each with 1 024 epochs of margin), so beyond a segment and a half the memory stays a segment's.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from process_throughput import timed  # noqa: E402  (benchmarks/ is on sys.path)
from trajectory_cost import LONG, simulated_drive  # noqa: E402


def quarter(path: Path, out: Path, header: bool, epochs: int) -> None:
    """The lines of ``path`` whose epoch is among its first ``epochs`` (libRSF: time stamp below; CSV: the first
    ``epochs`` distinct epoch keys)."""
    seen: list[str] = []
    with open(path) as src, open(out, "w") as dst:
        if header:
            columns = src.readline()
            dst.write(columns)
            key = columns.strip().split(",").index("millisSinceGpsEpoch")
        for line in src:
            fields = line.split(",") if header else line.split()
            stamp = fields[key] if header else fields[1]
            if not seen or seen[-1] != stamp:
                if len(seen) == epochs:
                    break
                seen.append(stamp)
            dst.write(line)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=40_000, help="the whole drive's epochs (5 Hz)")
    parser.add_argument("--longer", type=int, default=80_000, help="a longer drive's epochs (0: none)")
    args = parser.parse_args()
    folder = LONG if args.epochs == 40_000 else os.path.join(os.path.dirname(LONG), f"city-{args.epochs}")
    librsf = Path(simulated_drive(folder, args.epochs // 5))
    derived = librsf.with_name("drive-derived.csv")
    tollcli = [sys.executable, "-m", "tollcli", "integrity"]
    print(f"a simulated city drive of {args.epochs} epochs (5 Hz); tollcli integrity, wall time and peak RSS")
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, header in (("libRSF", librsf, False), ("GSDC derived CSV", derived, True)):
            part = Path(tmp) / f"quarter{path.suffix}"
            quarter(path, part, header, args.epochs // 4)
            runs = {}
            for label, log in (("quarter", part), ("whole", path)):
                runs[label] = timed([*tollcli, str(log), "-q", "-o", str(Path(tmp) / "table.csv")])
                print(f"  {name:16s} {label:7s} {log.stat().st_size / 1e6:5.0f} MB: {runs[label][0]:6.2f} s, peak RSS {runs[label][1]:6.0f} MB")
            print(f"  {name:16s} whole / quarter: time {runs['whole'][0] / runs['quarter'][0]:.2f}, peak RSS "
                  f"{runs['whole'][1] / runs['quarter'][1]:.2f}")  # fmt: skip
            if args.longer:
                longer = Path(simulated_drive(os.path.join(os.path.dirname(LONG), f"city-{args.longer}"), args.longer // 5))
                longer = longer.with_name(path.name)  # (the same format: the simulator writes both)
                runs["longer"] = timed([*tollcli, str(longer), "-q", "-o", str(Path(tmp) / "table.csv")])
                print(f"  {name:16s} {args.longer // 1000}k epochs {longer.stat().st_size / 1e6:5.0f} MB: {runs['longer'][0]:6.2f} s, "
                      f"peak RSS {runs['longer'][1]:6.0f} MB; {args.longer // 1000}k / {args.epochs // 1000}k: time "
                      f"{runs['longer'][0] / runs['whole'][0]:.2f}, peak RSS {runs['longer'][1] / runs['whole'][1]:.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
