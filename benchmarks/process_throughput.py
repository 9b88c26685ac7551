"""``tollcli process`` on a 10-hour 1 Hz drive through a network of 10 000 geo-objects.

The drive: ``compose.straight_drive`` (GPS+Galileo, 9 sentences per epoch), 36 000
epochs. The network: the motorway under the drive cut into 250 m tolled segments,
plus parallel tolled roads 200 m apart, all cut the same way, to 10 000
geo-objects (built by ``build_geoobjects``; HAL 50 m). Reported, each in a fresh
process: wall time and peak RSS of ``tollcli process``, and of ``tollcli epochs``
(the reader alone, the baseline) on the same log.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tollcli.charging.geoobjects import build_geoobjects
from tollcli.nmea.compose import straight_drive

START = (42.6987, 2.8956)
COURSE = math.radians(45.0)
SPEED = 13.9


def point(s_m: float, offset_m: float) -> list[float]:
    north = s_m * math.cos(COURSE) + offset_m * math.cos(COURSE - math.pi / 2)
    east = s_m * math.sin(COURSE) + offset_m * math.sin(COURSE - math.pi / 2)
    lat = START[0] + north / 111_132.0
    return [START[1] + east / (111_320.0 * math.cos(math.radians(START[0]))), lat]


def roads(n_objects: int, length_m: float, seg_m: float = 250.0) -> dict:
    per_road = int(length_m // seg_m)
    n_roads = math.ceil(n_objects / per_road)
    feats = []
    for r in range(n_roads):
        offset = 200.0 * ((r + 1) // 2) * (1 if r % 2 else -1)
        for k in range(per_road):
            if len(feats) == n_objects:
                break
            feats.append({"type": "Feature", "properties": {"id": f"R{r}-{k}", "road_class": "motorway"},
                          "geometry": {"type": "LineString", "coordinates": [point(k * seg_m, offset), point((k + 1) * seg_m, offset)]}})  # fmt: skip
    return {"type": "FeatureCollection", "features": feats}


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall time (s) and peak RSS (MB) of a command in a fresh process."""
    code = ("import resource, subprocess, sys, time\n"
            "t = time.perf_counter(); subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL)\n"
            "print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code, *cmd], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), int(out[1]) / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=10.0)
    parser.add_argument("--objects", type=int, default=10_000)
    args = parser.parse_args()
    n_epochs = int(args.hours * 3600)
    tollcli = [sys.executable, "-m", "tollcli"]
    tariff = Path(__file__).resolve().parents[1] / "geoobjects" / "example-tariff.toml"
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "drive.nmea"
        log.write_text("\n".join(straight_drive(n_epochs)) + "\n")
        road_file = Path(tmp) / "roads.geojson"
        road_file.write_text(json.dumps(roads(args.objects, n_epochs * SPEED)))
        start = time.perf_counter()
        geo = build_geoobjects(str(road_file))
        t_build = time.perf_counter() - start
        geo_file = Path(tmp) / "geo.geojson"
        geo_file.write_text(json.dumps(geo))
        print(f"drive: {n_epochs} epochs ({log.stat().st_size / 1e6:.0f} MB NMEA); network: {len(geo['features'])} geo-objects "
              f"(built in {t_build:.1f} s)")  # fmt: skip
        t_read, m_read = timed([*tollcli, "epochs", str(log), "-o", str(Path(tmp) / "e.parquet"), "-q"])
        t_proc, m_proc = timed([*tollcli, "process", str(log), "--geo", str(geo_file), "--tariff", str(tariff),
                                "-o", str(Path(tmp) / "invoice.json"), "-q"])  # fmt: skip
        invoice = json.loads((Path(tmp) / "invoice.json").read_text())
        print(f"tollcli epochs  (reader, baseline): {t_read:7.1f} s  {n_epochs / t_read:9,.0f} epochs/s  peak RSS {m_read:7.0f} MB")
        print(f"tollcli process (read+RAIM+charge): {t_proc:7.1f} s  {n_epochs / t_proc:9,.0f} epochs/s  peak RSS {m_proc:7.0f} MB")
        print(f"ratio process / reader time: {t_proc / t_read:.2f}; invoice: {len(invoice['lines'])} lines, total {invoice['total']}")


if __name__ == "__main__":
    main()
