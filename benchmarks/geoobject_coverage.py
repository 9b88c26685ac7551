"""How much of a real tolled network geo-objects cover, and at what HAL: the design HAL against the rule before it.

    python benchmarks/geoobject_coverage.py [--map ../shared/data/osm/helsinki.osm.pbf] [--tolled highway=primary]
                                            [--design 25 --design 25-50 ...] [--min-hal 25]

The baseline, named ``5-50 (before)``, is the rule earlier versions built with: HAL = min(50 m, half the distance to
the nearest road not met), a road cut around only when closer than 2 · 5 m (``--hal-min``). Each design HAL is
built from the same sections in the same run. Printed per design: geo-objects, sections skipped, sections below
their design HAL, median HAL, the tolled length covered in all and by geo-objects of HAL ≥ ``--min-hal``, and the
build time.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from tollcli.geoobjects.design_hal import parse_design_hal
from tollcli.geoobjects.info import covered_lengths_m
from tollcli.geoobjects.build import build_from_roads, fallbacks
from tollcli.geoobjects.osm_network import osm_roads
from tollcli.geoobjects.osm import read_osm_roads

REPO = Path(__file__).resolve().parents[1]
BASELINE = "5-50"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=str(REPO.parent / "shared" / "data" / "osm" / "helsinki.osm.pbf"))
    parser.add_argument("--tolled", action="append", default=None)
    parser.add_argument("--design", action="append", default=None, help="design HAL(s) to compare (default: 25 and 25-50)")
    parser.add_argument("--min-hal", type=float, default=25.0)
    args = parser.parse_args()
    roads = osm_roads(read_osm_roads(args.map), args.tolled or ["highway=primary"])
    print(f"{args.map}, tolled {' '.join(args.tolled or ['highway=primary'])}: {sum(p['tolled'] for p in roads.props)} sections")
    print(f"| design HAL (m) | geo-objects | skipped | below design | median HAL (m) | covered km (share) | at HAL ≥ {args.min_hal:g} m | build s |")
    print("|---|---|---|---|---|---|---|---|")
    for design in [BASELINE, *(args.design or ["25", "25-50"])]:
        t = time.perf_counter()
        doc, skipped = build_from_roads(roads, args.map, parse_design_hal([design]))
        elapsed = time.perf_counter() - t
        props = [f["properties"] for f in doc["features"]]
        tolled, covered, at_min = covered_lengths_m(props, skipped, args.min_hal)
        below = len(fallbacks(doc)) if design != BASELINE else 0
        name = f"{design} (before)" if design == BASELINE else design
        print(f"| {name} | {len(props)} | {len(skipped)} | {below} | {np.median([p['hal_m'] for p in props]):.1f} | "
              f"{covered / 1000:.3f} of {tolled / 1000:.3f} ({100 * covered / tolled:.1f} %) | "
              f"{at_min / 1000:.3f} ({100 * at_min / tolled:.1f} %) | {elapsed:.2f} |")


if __name__ == "__main__":
    main()
