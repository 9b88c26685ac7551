"""Geo-objects from a real OpenStreetMap extract: time of each stage, against the GeoJSON path on the same roads.

    python benchmarks/osm_build.py [--map ../shared/data/osm/helsinki.osm.pbf] [--tolled highway=primary] [--repeat 5]

Stages: reading the map (pyosmium), sections between junctions, building the geo-objects. The baseline is
building the same lines (sections and free ways) connected by 2-D touching, as a GeoJSON network is, in the same
run: the ratio says what reading the map and merging sections add. Best of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from tollcli.geoobjects.build import Roads, build_from_roads
from tollcli.geoobjects.osm_network import osm_roads
from tollcli.geoobjects.osm import read_osm_roads

REPO = Path(__file__).resolve().parents[1]


def _best(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default=str(REPO.parent / "shared" / "data" / "osm" / "helsinki.osm.pbf"))
    parser.add_argument("--tolled", action="append", default=None)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rules = args.tolled or ["highway=primary"]
    t_read, osm = _best(lambda: read_osm_roads(args.map), args.repeat)
    t_sections, roads = _best(lambda: osm_roads(osm, rules), args.repeat)
    t_build, (doc, skipped) = _best(lambda: build_from_roads(roads, args.map, hal_min_m=5.0), args.repeat)
    total = t_read + t_sections + t_build
    plain = Roads(roads.ids, roads.props, roads.lines, None)  # the same lines, connected by 2-D touching
    t_plain, _ = _best(lambda: build_from_roads(plain, args.map, hal_min_m=5.0), args.repeat)
    print(f"map {args.map}: {len(osm.ways)} drivable ways, {sum(p['tolled'] for p in roads.props)} tolled sections, "
          f"{len(doc['features'])} geo-objects, {len(skipped)} skipped")  # fmt: skip
    print(f"read {t_read:.3f} s  sections {t_sections:.3f} s  build {t_build:.3f} s  total {total:.3f} s")
    print(f"baseline: the build of the same lines without the map's topology {t_plain:.3f} s; "
          f"OSM total / baseline = {total / t_plain:.2f}")


if __name__ == "__main__":
    main()
