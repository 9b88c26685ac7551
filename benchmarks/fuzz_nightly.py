"""Run the fuzz suite (tests/test_fuzz.py) long and at random, for nightly use.

    python benchmarks/fuzz_nightly.py --examples 5000

Each fuzzer gets ``--examples`` random cases (CI runs a small fixed set); the
report lists cases tried per fuzzer and every failure with its minimal example.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=5000, help="random cases per fuzzer")
    args = parser.parse_args()
    env = dict(os.environ, FUZZ_EXAMPLES=str(args.examples))
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--hypothesis-show-statistics",
                           "tests/test_fuzz.py"], cwd=ROOT, env=env, capture_output=True, text=True)  # fmt: skip
    tried = [line.strip() for line in proc.stdout.splitlines() if " passing, " in line or line.startswith("tests/test_fuzz.py::")]
    print(f"fuzz run: {args.examples} examples per fuzzer, {time.perf_counter() - start:.0f} s")
    print("\n".join(tried))
    print(proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else "(no output)")
    if proc.returncode != 0:
        print(proc.stdout[-8000:])
    sys.exit(proc.returncode)


if __name__ == "__main__":
    main()
