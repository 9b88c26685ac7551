"""What authenticating a log costs: ``tollcli process`` on the real OSNMA u-blox recording
(``../shared/data/osnma/ublox/current_config.ubx``, 80 min, 104 000 UBX frames, 28 000 Galileo pages) with its
Merkle tree and public keys beside it (OSNMA checked), against the same bytes copied to a folder without them
(the baseline: no OSNMA), in turn, each in a fresh process, as an installed package runs (tollcli's bytecode
compiled first, ``PYTHONDONTWRITEBYTECODE`` dropped: an editable checkout under it would compile every module on
every start, and the OSNMA modules are more of them). Prints the medians of wall time and of CPU time (user + system,
children included: the verification runs in a forked process beside the charge) and their ratios (target ≤ 1.3).

    python benchmarks/osnma_cost.py [--runs 7]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "osnma" / "ublox"
LOG = DATA / "current_config.ubx"
TARIFF = 'currency = "EUR"\nminor_unit = 2\ntimezone = "Europe/Brussels"\n\n[road_class.motorway]\ncar = 0.95\n'


def _site(folder: Path) -> None:
    """A 560 m tolled road through the receiver's median position (HAL 50 m), and its tariff."""
    import numpy as np

    from tollcli.readers.ubx_nav import iter_ubx_nav_tables

    fixes = np.concatenate([c.epochs[["lat_deg", "lon_deg"]].to_numpy(float) for c in iter_ubx_nav_tables(LOG)])
    lat, lon = np.median(fixes, axis=0)
    road = {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {
        "id": "R1", "name": "site road", "road_class": "motorway", "tolled": True},
        "geometry": {"type": "LineString", "coordinates": [[lon - 0.004, lat], [lon + 0.004, lat]]}}]}  # fmt: skip
    (folder / "roads.geojson").write_text(json.dumps(road))
    (folder / "tariff.toml").write_text(TARIFF)
    subprocess.run([sys.executable, "-m", "tollcli", "geoobjects", "build", folder / "roads.geojson", "--hal", "50", "-o",
                    folder / "geo.geojson", "-q"], check=True)  # fmt: skip


ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def _seconds(cmd: list) -> tuple[float, float]:
    """Wall and CPU seconds of one run (CPU: the run's process and its children, from the OS accounting)."""
    before = os.times()
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=ENV)
    wall = time.perf_counter() - t
    after = os.times()
    return wall, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    if not LOG.exists():
        sys.exit(f"{LOG}: not present")
    import tollcli

    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(tollcli.__file__).parent)], check=True, env=ENV)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _site(folder)
        plain = folder / "plain" / "current_config.ubx"
        plain.parent.mkdir()
        shutil.copyfile(LOG, plain)

        def process(log: Path, out: str) -> list:
            return [sys.executable, "-m", "tollcli", "process", log, "--geo", folder / "geo.geojson", "--tariff",
                    folder / "tariff.toml", "--policy", "raim", "-o", folder / out, "-q"]  # fmt: skip

        keys, baseline = process(LOG, "keys.json"), process(plain, "plain.json")
        _seconds(keys), _seconds(baseline)  # warm-up: the page cache and the compiled bytecode
        pairs = [(_seconds(keys), _seconds(baseline)) for _ in range(args.runs)]
        checked = json.loads((folder / "keys.json").read_text())["navigation_authentication"]["checked"]
    for k, what in ((0, "wall"), (1, "CPU")):
        with_keys, without = statistics.median(p[0][k] for p in pairs), statistics.median(p[1][k] for p in pairs)
        ratio = statistics.median(a[k] / b[k] for a, b in pairs)
        print(f"{what}: process with OSNMA keys {with_keys:.2f} s (median of {args.runs}; checked: {checked}), "
              f"without (baseline) {without:.2f} s, ratio {ratio:.2f}")


if __name__ == "__main__":
    main()
