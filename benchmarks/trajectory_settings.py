"""How the trajectory estimator's settings were fixed: on the simulator's city drives first, then the real drive.

    python benchmarks/trajectory_settings.py            # ≈ 3 min (simulates the two city drives once, as integrity_truth.py)

The motion model's one free setting is the lateral slip, a random walk of the position beside what the odometer and
the gyro say (``MotionNoise.position_m2ps``). It is swept on the simulated city drives with odometry (10 000 epochs
each: fault-free, and with a 100 m satellite fault and an outage; ``integrity_truth.CITY_SIMULATIONS``); the value
with the smallest 95th-percentile error over both, among those with no misleading epoch, is the default. Then the
real Berlin drive is run with every value, to show what the choice gives there (it is not chosen on it).
Columns: horizontal error p50 / p95 / max (m), share of epochs with HPL ≤ 50 m and ≤ 30 m, misleading epochs
(error > HPL), the largest error / HPL.
"""

from __future__ import annotations

import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

from integrity_truth import city_drives  # noqa: E402

from tollcli.gnss.librsf_positions import librsf_epochs  # noqa: E402
from tollcli.integrity.trajectory import estimate_trajectory  # noqa: E402
from tollcli.integrity.trajectory_filter import MotionNoise  # noqa: E402
from tollcli.integrity.trajectory_inputs import trajectory_inputs  # noqa: E402
from tollcli.integrity.truth_check import errors_against_truth  # noqa: E402
from tollcli.readers.librsf import librsf_truth, read_librsf  # noqa: E402

SLIPS_M2PS = (0.003, 0.01, 0.03, 0.1, 0.3)
BERLIN = os.path.join(ROOT, "..", "shared", "data", "smartloc", "Berlin_Potsdamer_Platz_")


def figures(log: str, truth: str, slip: float) -> dict:
    epochs, meas = librsf_epochs(read_librsf(log))
    inp = trajectory_inputs(epochs, meas)
    traj = estimate_trajectory(inp, "smoothed", MotionNoise(position_m2ps=slip))
    lat, lon, _ = inp.enu2geodetic(traj.enu_m)
    err, _ = errors_against_truth(epochs.assign(lat_deg=lat, lon_deg=lon), librsf_truth(truth), tolerance_s=0.2)
    hpl = traj.hpl_m
    return {"p50": np.nanpercentile(err, 50), "p95": np.nanpercentile(err, 95), "max": np.nanmax(err),
            "v50": np.mean(hpl <= 50), "v30": np.mean(hpl <= 30), "MI": int(np.sum(err > hpl)), "ratio": np.nanmax(err / hpl)}  # fmt: skip


def row(name: str, slip: float, f: dict) -> str:
    return (f"| {name} | {slip:g} | {f['p50']:.1f} / {f['p95']:.1f} / {f['max']:.1f} | {100 * f['v50']:.1f} % / {100 * f['v30']:.1f} % | "
            f"{f['MI']} | {f['ratio']:.2f} |")  # fmt: skip


def main() -> int:
    print("| drive | lateral slip m²/s | error p50 / p95 / max m | HPL ≤ 50 / ≤ 30 m | MI | largest error/HPL |")
    print("|---|---:|---|---:|---:|---:|")
    score = {}
    for drive in city_drives():
        for slip in SLIPS_M2PS:
            f = figures(drive.log, drive.truth, slip)
            print(row(drive.name.split(" (")[0], slip, f), flush=True)
            score.setdefault(slip, []).append(np.inf if f["MI"] else f["p95"])
    chosen = min(SLIPS_M2PS, key=lambda s: max(score[s]))
    print(f"\nchosen on the simulator: lateral slip {chosen:g} m²/s (smallest worst p95 with no misleading epoch)\n")
    if os.path.exists(BERLIN + "Input.txt"):
        for slip in SLIPS_M2PS:
            print(row("Berlin Potsdamer Platz" + (" (chosen)" if slip == chosen else ""), slip,
                      figures(BERLIN + "Input.txt", BERLIN + "GT.txt", slip)), flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
