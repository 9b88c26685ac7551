"""Run the fuzz suites long and at random, for nightly use.

    python benchmarks/fuzz_nightly.py --examples 5000

* ``tests/test_fuzz.py``: each hypothesis fuzzer (NMEA logs, geo-object files, tariffs) gets ``--examples`` cases;
* ``tests/test_fuzz_inputs.py``: ``--examples`` seeded mutations in all of a real file of every input kind (UBX RAWX
  and NAV, gpsd JSON, GSDC derived and device_gnss CSV, GnssLogger, RINEX, RTKLIB .pos, libRSF, NMEA), each through
  ``info`` and ``integrity``.

CI runs a small fixed set of both. The report lists the cases tried and every failure (a hypothesis failure with its
minimal example; a mutation by its kind and number, which replays it: ``pytest tests/test_fuzz_inputs.py -k ubx-17``).
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
    parser.add_argument("--suite", choices=("all", "hypothesis", "inputs"), default="all",
                        help="hypothesis: tests/test_fuzz.py only; inputs: the mutations of real files only")
    args = parser.parse_args()
    env = dict(os.environ, FUZZ_EXAMPLES=str(args.examples))
    code = 0
    if args.suite in ("all", "hypothesis"):
        code = _hypothesis(env, args.examples)
    if args.suite in ("all", "inputs"):
        code = code or _inputs(env, args.examples)
    sys.exit(code)


def _hypothesis(env: dict, examples: int) -> int:
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--hypothesis-show-statistics",
                           "tests/test_fuzz.py"], cwd=ROOT, env=env, capture_output=True, text=True)  # fmt: skip
    tried = [line.strip() for line in proc.stdout.splitlines() if " passing, " in line or line.startswith("tests/test_fuzz.py::")]
    print(f"fuzz run: {examples} examples per fuzzer, {time.perf_counter() - start:.0f} s")
    print("\n".join(tried))
    print(proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else "(no output)")
    if proc.returncode != 0:
        print(proc.stdout[-8000:])
    return proc.returncode


def _inputs(env: dict, examples: int) -> int:
    start = time.perf_counter()
    inputs = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf", "tests/test_fuzz_inputs.py"],
                            cwd=ROOT, env=env, capture_output=True, text=True)  # fmt: skip
    failed = [line for line in inputs.stdout.splitlines() if line.startswith("FAILED")]
    print(f"\nmutations of real files: {examples} cases over every input kind (each through the commands that read it), "
          f"{time.perf_counter() - start:.0f} s")
    print(inputs.stdout.strip().splitlines()[-1] if inputs.stdout.strip() else "(no output)")
    print("\n".join(failed))
    return inputs.returncode


if __name__ == "__main__":
    main()
