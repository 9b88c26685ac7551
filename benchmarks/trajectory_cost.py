"""What the trajectory estimator (``--positioning smoothed``) costs, against reading the same log and solving its
snapshot positions, in the same run.

    python benchmarks/trajectory_cost.py [--log FILE ...] [--rounds 5] [--twin-epochs 300] [--memory [N ...]]

Default logs: the real Berlin drive (``../shared/data/smartloc``, 1 372 epochs with odometry) and a simulated city
drive of 10 000 epochs (``tollcli simulate --nlos --odometry --duration 2000 --rate 5 --seed 11``, the one
``integrity_truth.py`` writes into ``benchmarks/integrity_truth/sim/city-clean``; written there if missing). Prints, per
log, the median over the rounds of the snapshot WLS (reader + solver, ``pseudorange_epochs``) and of the estimator on
its output, their ratio, and the estimator's epochs per second (it makes 7 passes over the log: a forward pass to
scale the noise, forward and backward, then two rounds of noise from the residuals with both again; the two passes
of a pair run on two threads); and the estimator's peak memory (``tracemalloc``), in covariance matrices per epoch. Then the same for the pure-Python twin of the compiled kernel (what an install without
a C compiler runs) on the log's first ``--twin-epochs`` epochs, with the compiled kernel on the same epochs beside it.
``--memory``: the estimator's peak memory and speed on the first N epochs (default 10 000, 20 000, 40 000) of a 40 000-epoch
simulated drive (``--duration 8000``, written once into ``sim/city-long``), swept whole and in chunks
(:mod:`tollcli.integrity.trajectory_sweep`): whole, the passes' covariances grow with the log; in chunks they do not.
``--against TREE``: the estimator on the simulated drive timed in turn with the code in TREE (a git worktree with its
kernel built: ``python setup.py build_ext --inplace``), each in a process of its own, ``--pairs`` times; prints both
medians and the median of the pairs' ratios (this machine's speed drifts by a quarter within minutes: only times
taken back to back compare code).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import subprocess
import sys
import time
import tracemalloc

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from tollcli.gnss.pseudorange_inputs import pseudorange_epochs  # noqa: E402
from tollcli.gnss.sigma_models import NominalModel  # noqa: E402
from tollcli.integrity import trajectory_filter, trajectory_sweep  # noqa: E402
from tollcli.integrity.trajectory import estimate_trajectory  # noqa: E402
from tollcli.integrity.trajectory_filter import MOTION_STATES  # noqa: E402
from tollcli.integrity.trajectory_inputs import trajectory_inputs  # noqa: E402

BERLIN = os.path.join(ROOT, "..", "shared", "data", "smartloc", "Berlin_Potsdamer_Platz_Input.txt")
SIMULATED = os.path.join(ROOT, "benchmarks", "integrity_truth", "sim", "city-clean")


def simulated_drive(folder: str = SIMULATED, duration_s: int = 2000) -> str:
    """A simulated city drive with odometry at 5 Hz, written once into ``folder`` (default: the 10 000-epoch one)."""
    log = os.path.join(folder, "drive-librsf.txt")
    if not os.path.exists(log):
        subprocess.run([sys.executable, "-m", "tollcli", "simulate", "--nlos", "--odometry", "--duration", str(duration_s), "--rate",
                        "5", "--seed", "11", "-o", folder, "-q"], check=True)  # fmt: skip
    return log


#: a 40 000-epoch drive (8 000 s at 5 Hz) for ``--memory``: written once (≈ 80 s)
LONG = os.path.join(ROOT, "benchmarks", "integrity_truth", "sim", "city-long")


def memory_by_length(lengths: list[int]) -> None:
    """The estimator's peak memory (tracemalloc, beyond its inputs) on the first ``lengths`` epochs of the long drive,
    swept whole and in chunks (trajectory_sweep), and its speed each way."""
    epochs, meas = pseudorange_epochs(simulated_drive(LONG, 8000), "librsf", None, "nominal", 5.0, NominalModel())
    full = trajectory_inputs(epochs, meas)
    print(f"memory by log length (the long simulated drive; chunks of {trajectory_sweep.CHUNK_EPOCHS} epochs; "
          f"default: whole up to {trajectory_sweep.CHUNKED_FROM_EPOCHS} epochs)")  # fmt: skip
    threshold = trajectory_sweep.CHUNKED_FROM_EPOCHS
    for n in lengths:
        inp = _stretch(full, min(n, full.t_s.size))
        inputs = sum(a.nbytes for a in inp.kernel_arrays)
        for mode, chunked_from in (("whole", 1 << 62), ("chunked", 0)):
            trajectory_sweep.CHUNKED_FROM_EPOCHS = chunked_from
            t0 = time.perf_counter()
            estimate_trajectory(inp, "smoothed")
            seconds = time.perf_counter() - t0
            tracemalloc.start()
            estimate_trajectory(inp, "smoothed")
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            m = inp.t_s.size
            print(f"  {m:6d} epochs {mode:7s}: peak {peak / 1e6:6.1f} MB = {peak / m:5.0f} B/epoch (its inputs {inputs / m:4.0f} "
                  f"B/epoch); {m / seconds:,.0f} epochs/s")  # fmt: skip
    trajectory_sweep.CHUNKED_FROM_EPOCHS = threshold


def _stretch(inp, n):
    return dataclasses.replace(inp, **{f.name: getattr(inp, f.name)[:n] for f in dataclasses.fields(inp)
                                       if f.name not in ("origin_ecef_m", "ecef2enu")})  # fmt: skip


def _timed(fn, rounds):
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


#: what each process of ``--against`` runs: the estimator on the log, median of the rounds after one untimed, in seconds
ESTIMATOR_SECONDS = """
import statistics, sys, time
sys.path.insert(0, sys.argv[1])
import tollcli
assert tollcli.__file__.startswith(sys.argv[1]), tollcli.__file__
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity.trajectory import estimate_trajectory
from tollcli.integrity.trajectory_inputs import trajectory_inputs
epochs, meas = pseudorange_epochs(sys.argv[2], "librsf", None, "nominal", 5.0, NominalModel())
estimate_trajectory(trajectory_inputs(epochs, meas), "smoothed")
times = []
for _ in range(int(sys.argv[3])):
    t0 = time.perf_counter()
    estimate_trajectory(trajectory_inputs(epochs, meas), "smoothed")
    times.append(time.perf_counter() - t0)
print(statistics.median(times), len(epochs))
"""


def against(tree: str, pairs: int, rounds: int) -> None:
    """The estimator on the simulated drive, this code (A) and the code in ``tree`` (B) in turn, ``pairs`` times."""
    log = simulated_drive()
    rows = []
    for _ in range(pairs):
        pair = [subprocess.run([sys.executable, "-c", ESTIMATOR_SECONDS, root, log, str(rounds)], check=True, capture_output=True,
                               text=True).stdout.split() for root in (ROOT, os.path.abspath(tree))]  # fmt: skip
        rows.append([float(seconds) for seconds, _n in pair])
        n = int(pair[0][1])
    a, b = statistics.median(r[0] for r in rows), statistics.median(r[1] for r in rows)
    print(f"estimator on {os.path.basename(os.path.dirname(log))} ({n} epochs), {pairs} pairs (median of {rounds} rounds each): "
          f"this code {a * 1e3:.1f} ms ({n / a:,.0f} epochs/s), {tree} {b * 1e3:.1f} ms ({n / b:,.0f}); median of the pair ratios "
          f"{statistics.median(r[0] / r[1] for r in rows):.3f}")  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", nargs="*", default=None, help="libRSF logs (default: Berlin and the simulated drive)")
    parser.add_argument("--kind", default="librsf")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--twin-epochs", type=int, default=300)
    parser.add_argument("--memory", type=int, nargs="*", default=None,
                        help="also the peak memory on the first N epochs of a 40 000-epoch simulated drive, whole and in chunks "
                        "(no N: 10000 20000 40000)")  # fmt: skip
    parser.add_argument("--against", metavar="TREE", help="time the estimator in turn with the code in TREE (see above)")
    parser.add_argument("--pairs", type=int, default=8, help="pairs for --against (default 8)")
    args = parser.parse_args()
    if args.against:
        against(args.against, args.pairs, args.rounds)
        return 0
    logs = args.log if args.log else [p for p in (BERLIN, simulated_drive()) if os.path.exists(p)]
    compiled = trajectory_filter._kernel() is not None
    print(f"compiled kernel: {'yes' if compiled else 'NOT BUILT (the Python twin runs)'}; median of {args.rounds} rounds")
    for log in logs:
        t_snap, (epochs, meas) = _timed(lambda: pseudorange_epochs(log, args.kind, None, "nominal", 5.0, NominalModel()), args.rounds)
        t_est, traj = _timed(lambda: estimate_trajectory(trajectory_inputs(epochs, meas), "smoothed"), args.rounds)
        n = len(epochs)
        print(f"{os.path.basename(os.path.dirname(log)) if 'sim' in log else os.path.basename(log)}: {n} epochs; "
              f"snapshot {t_snap:.3f} s, estimator {t_est:.3f} s: ratio {t_est / t_snap:.2f}; {n / t_est:,.0f} epochs/s "
              f"(odometry: {traj.odometry})")  # fmt: skip
        inp = trajectory_inputs(epochs, meas)
        _ = inp.kernel_arrays  # (the inputs' own arrays, made before)
        tracemalloc.start()
        estimate_trajectory(inp, "smoothed")
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        s = MOTION_STATES + inp.n_clocks
        print(f"  memory: the estimator's peak {peak / 1e6:.1f} MB = {peak / n / (8 * s * s):.1f} covariance matrices "
              f"({s}×{s}) per epoch")  # fmt: skip
        if compiled and args.twin_epochs:
            short = _stretch(trajectory_inputs(epochs, meas), min(args.twin_epochs, n))
            t_fast, _ = _timed(lambda: estimate_trajectory(short, "smoothed"), args.rounds)
            os.environ["TOLLCLI_KERNELS"] = "numpy"
            t_twin, _ = _timed(lambda: estimate_trajectory(short, "smoothed"), 1)
            del os.environ["TOLLCLI_KERNELS"]
            m = short.t_s.size
            print(f"  first {m} epochs: compiled {m / t_fast:,.0f} epochs/s, Python twin {m / t_twin:,.0f} epochs/s "
                  f"(×{t_twin / t_fast:.0f})")  # fmt: skip
    if args.memory is not None:
        memory_by_length(args.memory or [10_000, 20_000, 40_000])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
