"""What the trajectory estimator (``--positioning smoothed``) costs, against reading the same log and solving its
snapshot positions, in the same run.

    python benchmarks/trajectory_cost.py [--log FILE] [--rounds 3]

Default log: the real Berlin drive (``../shared/data/smartloc``, 1 372 epochs with odometry). Prints, per round, the
seconds of the snapshot WLS (reader + solver, ``pseudorange_epochs``) and of the estimator on its output, the ratio
estimator / snapshot, and the estimator's epochs per second and epoch-steps per second (it makes
7 passes over the log: a forward pass to scale the noise, forward and backward, then two rounds of noise from the
residuals with both again).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from tollcli.gnss.pseudorange_inputs import pseudorange_epochs  # noqa: E402
from tollcli.gnss.sigma_models import NominalModel  # noqa: E402
from tollcli.integrity.trajectory import estimate_trajectory  # noqa: E402
from tollcli.integrity.trajectory_inputs import trajectory_inputs  # noqa: E402

BERLIN = os.path.join(ROOT, "..", "shared", "data", "smartloc", "Berlin_Potsdamer_Platz_Input.txt")
PASSES = 7


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", default=BERLIN)
    parser.add_argument("--kind", default="librsf")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    if not os.path.exists(args.log):
        sys.exit(f"{args.log}: not present")
    for k in range(args.rounds):
        t0 = time.perf_counter()
        epochs, meas = pseudorange_epochs(args.log, args.kind, None, "nominal", 5.0, NominalModel())
        t1 = time.perf_counter()
        traj = estimate_trajectory(trajectory_inputs(epochs, meas), "smoothed")
        t2 = time.perf_counter()
        n = len(epochs)
        print(f"round {k}: {n} epochs; snapshot {t1 - t0:.2f} s, estimator {t2 - t1:.2f} s: ratio {(t2 - t1) / (t1 - t0):.1f}; "
              f"{n / (t2 - t1):,.0f} epochs/s, {PASSES * n / (t2 - t1):,.0f} epoch-steps/s (odometry: {traj.odometry})")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
