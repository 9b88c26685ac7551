"""Regenerate the example city: ``python samples/make_city.py`` (deterministic).

A Gothenburg-like town (centre 57.707 N, 11.967 E, local metric frame) in ``../geoobjects/``:

* ``example-city-roads.geojson``: eight radial roads R1 … R8 from the centre out to 3 km (R1 north, then every 45°
  clockwise), a road P3 parallel to R3 (east) 30 m north of it from 1.2 to 1.9 km, and a cross street C3 across R3
  30 m outside the cordon (parallel to its gantry's line);
* ``example-city-gantries.geojson``: a cordon of eight gantry points G1 … G8, one on each radial 1.5 km out;
* ``example-city-zone.geojson``: the zone Z1, an octagon 700 m around the centre;
* ``example-city.geojson``: what ``tollcli geoobjects build example-city-roads.geojson --gantries … --zones …`` makes
  of them (G3's HAL is bounded by P3).

Driving a radial road as drawn goes outward: it crosses its gantry ``left_to_right``.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
GEO = HERE.parent / "geoobjects"
CENTRE = (57.7070, 11.9670)  # lat, lon
CORDON_M = 1500.0


def at(east_m: float, north_m: float) -> list[float]:
    """[lon, lat] of a point east/north of the centre, m (a local tangent plane: exact enough at 3 km)."""
    lat = CENTRE[0] + north_m / 111_300.0
    lon = CENTRE[1] + east_m / (111_300.0 * math.cos(math.radians(CENTRE[0])))
    return [round(lon, 7), round(lat, 7)]


def radial(bearing_deg: float, r_m: float, offset_m: float = 0.0) -> list[float]:
    """[lon, lat] r metres out along a bearing, offset metres to the left of the outward direction."""
    b = math.radians(bearing_deg)
    e, n = r_m * math.sin(b), r_m * math.cos(b)
    return at(e - offset_m * math.cos(b), n + offset_m * math.sin(b))


def feature(props: dict, kind: str, coords) -> dict:
    return {"type": "Feature", "properties": props, "geometry": {"type": kind, "coordinates": coords}}


def main() -> None:
    roads = [feature({"id": f"R{k + 1}", "name": f"Radial {k + 1}", "road_class": "primary"}, "LineString",
                     [radial(45.0 * k, r) for r in (0.0, 1000.0, 2000.0, 3000.0)]) for k in range(8)]  # fmt: skip
    roads.append(feature({"id": "P3", "name": "Parallel to R3", "road_class": "residential"}, "LineString",
                         [radial(90.0, r, 30.0) for r in (1200.0, 1900.0)]))  # fmt: skip
    c3 = [radial(90.0, CORDON_M + 30.0, o) for o in (-300.0, 300.0)]
    roads.append(feature({"id": "C3", "name": "Cross street at R3", "road_class": "residential"}, "LineString", c3))
    points = [feature({"id": f"G{k + 1}", "name": f"Cordon {k + 1}"}, "Point", radial(45.0 * k, CORDON_M)) for k in range(8)]
    zone = [feature({"id": "Z1", "name": "City centre", "hal_m": 50}, "Polygon",
                    [[radial(22.5 + 45.0 * k, 700.0) for k in range(8)] + [radial(22.5, 700.0)]])]  # fmt: skip
    for name, features in (("example-city-roads.geojson", roads), ("example-city-gantries.geojson", points),
                           ("example-city-zone.geojson", zone)):  # fmt: skip
        (GEO / name).write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=1) + "\n", encoding="utf-8")
    subprocess.run([sys.executable, "-m", "tollcli", "geoobjects", "build", str(GEO / "example-city-roads.geojson"), "--gantries",
                    str(GEO / "example-city-gantries.geojson"), "--zones", str(GEO / "example-city-zone.geojson"), "--quiet",
                    "-o", str(GEO / "example-city.geojson")], check=True)  # fmt: skip


if __name__ == "__main__":
    main()
