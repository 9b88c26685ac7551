"""The trajectory's verdicts where a drive has too few satellites: at its start, in its middle or at its end, with and
without odometry, audited against the simulator's truth.

    python benchmarks/trajectory_ends.py [--duration 1200] [--stretch 120] [--seed 13] [--only middle-gap]

A simulated city drive (``tollcli simulate --nlos --odometry --duration D --rate 5 --seed S``, written once into a
temporary folder) is edited: in a stretch of ``--stretch`` seconds at the start, in the middle or at the end, each
epoch keeps only its first k pseudoranges (k = 3, 2, 1), or the receiver logs nothing (a gap: the middle only); and
the same without its odometry lines. Each edited drive goes through ``tollcli integrity`` (defaults: smoothed
positions) and ``tollcli audit --epochs … --truth truth-librsf.txt``. Printed per case: valid epochs, faults,
misleading and hazardous (HAL 50 m), and the smoothed error's 95th percentile and largest. Every case must show 0
misleading and 0 hazardous; a stretch at an end must not turn the drive into faults (a pass that started at an epoch
without a fix, from a fix a stretch away as certain as at a fix, did: ``tollcli/integrity/trajectory.py``,
``START_SPEED_MPS``).
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def edited(drive: Path, out: Path, lo: float, hi: float, keep: int | None, odometry: bool) -> None:
    """``drive`` with the stretch [lo, hi) s cut to ``keep`` pseudoranges an epoch (None: nothing logged there), and
    without its odometry lines unless ``odometry``."""
    lines, count = [], {}
    for line in drive.read_text().splitlines(keepends=True):
        kind, t = line.split()[0], float(line.split()[1])
        if kind == "odom3" and not odometry:
            continue
        if lo <= t < hi:
            if keep is None:
                continue
            if kind == "pseudorange3":
                count[t] = count.get(t, 0) + 1
                if count[t] > keep:
                    continue
        lines.append(line)
    out.write_text("".join(lines))


def tollcli(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "tollcli", *args], check=True, capture_output=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1200.0, help="the drive (s, at 5 Hz)")
    parser.add_argument("--stretch", type=float, default=120.0, help="the stretch with few satellites (s)")
    parser.add_argument("--seed", type=int, default=13)
    parser.add_argument("--only", nargs="*", default=None, metavar="STRETCH-K",
                        help="only these cases, e.g. middle-gap start-2 (default: all)")
    args = parser.parse_args()
    d, s = args.duration, args.stretch
    where = {"start": (0.0, s), "middle": ((d - s) / 2, (d + s) / 2), "end": (d - s, d)}
    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        tollcli("simulate", "--nlos", "--odometry", "--duration", f"{d:g}", "--rate", "5", "--seed", str(args.seed), "-o", str(sim), "-q")
        print(f"a simulated city drive of {d:g} s at 5 Hz (seed {args.seed}); a {s:g} s stretch with k satellites; "
              "smoothed positions, HAL 50 m")  # fmt: skip
        print("| stretch | k | odometry | epochs | valid | faults | misleading | hazardous | error p95 (m) | error max (m) |")
        print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
        bad = 0
        for name, (lo, hi) in where.items():
            for keep in ([3, 2, 1, None] if name == "middle" else [3, 2, 1]):
                if args.only is not None and f"{name}-{'gap' if keep is None else keep}" not in args.only:
                    continue
                for odometry in (True, False):
                    log, table, report = Path(tmp) / "drive.txt", Path(tmp) / "epochs.csv", Path(tmp) / "audit.json"
                    edited(sim / "drive-librsf.txt", log, lo, hi, keep, odometry)
                    tollcli("integrity", str(log), "-o", str(table), "-q")
                    tollcli("audit", "--epochs", str(table), "--truth", str(sim / "truth-librsf.txt"), "-o", str(report), "-q")
                    audit = json.loads(report.read_text())["integrity"]
                    with open(table, newline="") as f:
                        status = np.array([row["raim_status"] for row in csv.DictReader(f)])
                    regions, error = audit["regions"], audit["horizontal_error_m"]
                    bad += regions["misleading"] + regions["hazardous"]
                    print(f"| {name} | {'gap' if keep is None else keep} | {'yes' if odometry else 'no'} | {status.size} | "
                          f"{int((status == 'valid').sum())} | {int((status == 'fault_detected').sum())} | {regions['misleading']} | "
                          f"{regions['hazardous']} | {error['p95']:.1f} | {error['max']:.1f} |")  # fmt: skip
        print(f"misleading or hazardous epochs in all: {bad}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
