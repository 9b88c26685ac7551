"""Regenerate the bundled samples: ``python samples/make_samples.py`` (deterministic).

* ``straight-drive.nmea``: 180 s of a 50 km/h GPS+Galileo drive near Perpignan
  (NMEA 4.10: RMC, VTG, GGA, GSA with system ids, GSV with signal ids, GST), with
  a comment header and one sentence whose checksum was damaged in transit, so
  the reader's skip report has something to say.
* ``../geoobjects/example-roads.geojson``: motorway A9 along that drive in two tolled
  segments meeting at a junction, and a free road 80 m to its left (so HAL = 40 m);
  ``../geoobjects/example-geoobjects.geojson`` is what ``tollcli geoobjects build`` makes of it.
* ``sim/<name>/``: simulated drives along that motorway (``tollcli simulate``), urban and
  rural, with and without faults: NMEA log, GSDC derived CSV, truth trajectory, the
  geo-objects really driven and a manifest with the command that made each (``DRIVES``).
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

from tollcli.geoobjects.build import build_geoobjects
from tollcli.readers.nmea.compose import straight_drive

HERE = Path(__file__).resolve().parent
GEO = HERE.parent / "geoobjects"
START = (42.6987, 2.8956)  # the drive's first fix
COURSE_DEG = 45.0


def along(s_m: float, offset_m: float = 0.0) -> list[float]:
    """[lon, lat] of a point s metres along the drive's course, offset metres to its left."""
    c, o = math.radians(COURSE_DEG), math.radians(COURSE_DEG - 90.0)
    north = s_m * math.cos(c) + offset_m * math.cos(o)
    east = s_m * math.sin(c) + offset_m * math.sin(o)
    lat = START[0] + north / 111_132.0
    lon = START[1] + east / (111_320.0 * math.cos(math.radians(START[0])))
    return [round(lon, 8), round(lat, 8)]


def roads() -> dict:
    """Motorway A9 along the drive in two tolled segments, a free road 80 m to its left."""
    def road(props, points):
        return {"type": "Feature", "properties": props, "geometry": {"type": "LineString", "coordinates": points}}

    return {"type": "FeatureCollection", "features": [
        road({"id": "A9-N1", "name": "A9 Perpignan-Nord 1", "road_class": "motorway"}, [along(-300), along(1250)]),
        road({"id": "A9-N2", "name": "A9 Perpignan-Nord 2", "road_class": "motorway"}, [along(1250), along(2900)]),
        road({"id": "D900", "name": "D900 (free)", "road_class": "primary", "tolled": False}, [along(-300, 80), along(2900, 80)]),
    ]}  # fmt: skip


#: simulated drives: name → options of ``tollcli simulate`` (route, geo-objects and output added)
DRIVES = {
    "rural-clean": ["--env", "rural", "--seed", "1"],
    "urban-clean": ["--env", "urban", "--seed", "2"],
    "urban-fault": ["--env", "urban", "--seed", "3", "--fault-bias", "80", "--fault-at", "60,150", "--fault-duration", "20"],
    "rural-fault": ["--env", "rural", "--seed", "4", "--fault-bias", "60", "--fault-prob", "0.2"],
}


def simulate_drives(here: Path, geo: Path) -> None:
    """Run ``tollcli simulate`` for every drive of ``DRIVES`` (paths relative to the repository root)."""
    root = HERE.parent
    for name, options in DRIVES.items():
        out = here / "sim" / name
        args = ["simulate", "--route", os.path.relpath(geo / "example-roads.geojson", root), "--via", "A9-N1,A9-N2",
                "--geo", os.path.relpath(geo / "example-geoobjects.geojson", root), *options, "-q", "-o", os.path.relpath(out, root)]  # fmt: skip
        subprocess.run([sys.executable, "-m", "tollcli", *args], check=True, cwd=root)


def main() -> None:
    lines = list(straight_drive(180))
    damaged = 100
    lines[damaged] = lines[damaged][:-2] + ("00" if lines[damaged][-2:] != "00" else "01")
    header = [
        "# tollcli sample: straight drive, 180 epochs at 1 Hz, 13.9 m/s, course 45 deg",
        "# made by samples/make_samples.py; line 103 has a damaged checksum on purpose",
    ]
    (HERE / "straight-drive.nmea").write_text("\n".join(header + lines) + "\n", encoding="ascii")
    (GEO / "example-roads.geojson").write_text(json.dumps(roads(), indent=1) + "\n")
    built = build_geoobjects(str(GEO / "example-roads.geojson"))
    (GEO / "example-geoobjects.geojson").write_text(json.dumps(built, separators=(",", ":"), sort_keys=True) + "\n")
    simulate_drives(HERE, GEO)


if __name__ == "__main__":
    main()
