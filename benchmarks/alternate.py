"""Two commands timed in turn, A then B, N times: their medians and the median of the pair ratios A/B.

    python benchmarks/alternate.py -n 10 --a "CMD A" --b "CMD B"

This machine's speed can drift by a quarter within minutes, so two figures timed minutes apart compare the machine,
not the code. Timed back to back, pair by pair, each pair sees the same machine; the median of the pairs' ratios is
what the A/B claims in the changelog and ``docs/scaling.md`` quote. Per run: the wall time, and the CPU time the
command's processes used (user + system, all threads: ``os.wait4``). A command runs through the shell; its output is
discarded (``--show`` keeps it). The code before a change is run from a git worktree of it, e.g.::

    git worktree add /tmp/before HEAD~1 && (cd /tmp/before && python setup.py build_ext --inplace)
    python benchmarks/alternate.py -n 10 \\
        --a "python -m tollcli epochs drive.nmea -o /dev/null" \\
        --b "env PYTHONPATH=/tmp/before python -m tollcli epochs drive.nmea -o /dev/null"

(an editable install finds ``tollcli`` in its own tree first: ``PYTHONPATH`` puts the worktree before it).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time


def timed(command: str, show: bool) -> tuple[float, float]:
    """Wall and CPU seconds (user + system of the command's processes) of one run of ``command``."""
    out = None if show else subprocess.DEVNULL
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, shell=True, stdout=out, stderr=out)
    _pid, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"alternate.py: {command!r} exited with {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=10, help="pairs (default 10)")
    parser.add_argument("--a", required=True, help="the command measured (A)")
    parser.add_argument("--b", required=True, help="the baseline (B)")
    parser.add_argument("--warm", type=int, default=1, help="untimed runs of each first (default 1)")
    parser.add_argument("--show", action="store_true", help="keep the commands' output")
    args = parser.parse_args(argv)
    for _ in range(args.warm):
        timed(args.a, args.show)
        timed(args.b, args.show)
    pairs = []
    for i in range(args.n):
        a, b = timed(args.a, args.show), timed(args.b, args.show)
        pairs.append((a, b))
        print(f"pair {i + 1:2d}: A {a[0]:.3f} s ({a[1]:.3f} s CPU)  B {b[0]:.3f} s ({b[1]:.3f} s CPU)  A/B {a[0] / b[0]:.3f}", file=sys.stderr)
    for what, k in (("wall", 0), ("CPU", 1)):
        a_med, b_med = statistics.median(p[0][k] for p in pairs), statistics.median(p[1][k] for p in pairs)
        ratio = statistics.median(p[0][k] / p[1][k] for p in pairs)
        print(f"{what}: A median {a_med:.3f} s, B median {b_med:.3f} s; median of the {args.n} pair ratios A/B {ratio:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
