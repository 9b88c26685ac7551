"""What verifying the compiled store costs: warm ``process`` on a national network, verified against unverified.

    python benchmarks/store_verification.py                     # 150 000 sections, a 1 h drive, 3 runs each
    python benchmarks/store_verification.py --sections 10000 --hours 10

The network and drive are ``national_network.py``'s (``process_throughput.roads`` scaled to the section count;
the 25 m/s drive with a real u-blox ZED-F9P's sentences). The store is compiled once by ``geoobjects build``; then,
alternating, in fresh processes:

* ``verified`` — ``tollcli process`` as shipped: every file of the store checked against its manifest's SHA-256
  before use (:mod:`tollcli.geoobjects.store_files`);
* ``unverified`` (the baseline) — the same command with the store's files mapped without any check, as before the
  manifest (``read_verified`` replaced by a plain mapping of the files it names).

Printed: each one's minimum and median wall time, the ratio verified / unverified (the target: ≤ 1.1), the
store's size and the time of ``load_geoobjects`` alone each way (and verified with every file hashed, as the first
run after a compile does), and whether both invoices are byte-identical.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from process_throughput import UBLOX_SPEED, roads, ublox_drive  # noqa: E402  (benchmarks/ is on sys.path)

TARIFF = Path(__file__).resolve().parents[1] / "geoobjects" / "example-tariff.toml"

#: the baseline: the store's files mapped as they are, without a check (as before the manifest)
PATCH = """
import json
import numpy as np
from tollcli.geoobjects import store, store_files

def unverified(folder, fmt, source):
    manifest = json.loads((folder / "manifest.json").read_text())
    columns = {"strings": json.loads((folder / "strings.json").read_text())}
    for name in manifest["files"]:
        if name.endswith(".npy"):
            columns[name[:-4]] = np.load(folder / name, mmap_mode="r", allow_pickle=False)
    return columns, store_files.manifest_sha256(manifest)

store.read_verified = unverified
"""
UNVERIFIED = PATCH + "import sys\nfrom tollcli.cli.main import main\nmain(sys.argv[1:])\n"
LOAD = "import sys, time\nt = time.perf_counter()\nfrom tollcli.geoobjects import store\n{patch}\nstore.load_geoobjects(sys.argv[1])\nprint(time.perf_counter() - t)\n"


def wall(cmd: list[str], env: dict) -> float:
    start = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sections", type=int, default=150_000)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        env = {**os.environ, "TOLLCLI_CACHE_DIR": str(work / "cache")}
        road_file, geo = work / "roads.geojson", work / "geo.geojson"
        road_file.write_text(json.dumps(roads(args.sections, 36000 * UBLOX_SPEED)))
        subprocess.run([sys.executable, "-m", "tollcli", "geoobjects", "build", str(road_file), "-o", str(geo), "-q"], env=env, check=True)
        drive = work / "drive.nmea"
        ublox_drive(drive, int(args.hours * 3600))
        store = next((work / "cache" / "geoobjects").glob("*.v*"))
        size_mb = sum(f.stat().st_size for f in store.iterdir()) / 1e6
        charge = ["process", str(drive), "--geo", str(geo), "--tariff", str(TARIFF), "-q"]
        commands = {"verified": [sys.executable, "-m", "tollcli", *charge, "-o", str(work / "verified.json")],
                    "unverified": [sys.executable, "-c", UNVERIFIED, *charge, "-o", str(work / "unverified.json")]}  # fmt: skip
        times: dict[str, list[float]] = {k: [] for k in commands}
        for name, cmd in commands.items():
            wall(cmd, env)  # warm the page cache and the threshold tables
        for _ in range(args.runs):
            for name, cmd in commands.items():
                times[name].append(wall(cmd, env))
        loads = {}
        for name, patch in (("verified", ""), ("unverified", PATCH)):
            code = LOAD.format(patch=patch)
            loads[name] = min(float(subprocess.run([sys.executable, "-c", code, str(geo)], env=env, check=True, capture_output=True,
                                                   text=True).stdout) for _ in range(args.runs))  # fmt: skip
        first = []
        for _ in range(args.runs):  # the first run after a compile (or a change) hashes every file
            (store / "verified").unlink(missing_ok=True)
            first.append(float(subprocess.run([sys.executable, "-c", LOAD.format(patch=""), str(geo)], env=env, check=True,
                                              capture_output=True, text=True).stdout))  # fmt: skip
        loads["verified, every file hashed"] = min(first)
        same = (work / "verified.json").read_bytes() == (work / "unverified.json").read_bytes()
    print(f"{args.sections} sections, store {size_mb:.0f} MB, a {args.hours:g} h drive; {args.runs} runs each, warm")
    for name in commands:
        print(f"  {name:10s} process min {min(times[name]):6.2f} s  median {statistics.median(times[name]):6.2f} s   "
              f"load_geoobjects {loads[name]:.3f} s")  # fmt: skip
    print(f"  load_geoobjects when every file is hashed (the first run after a compile): {loads['verified, every file hashed']:.3f} s")
    ratio = statistics.median(times["verified"]) / statistics.median(times["unverified"])
    print(f"  verified / unverified (median): {ratio:.3f}x (target <= 1.1); invoices byte-identical: {same}")


if __name__ == "__main__":
    main()
