"""Simulated drives through the example city (``geoobjects/example-city.geojson``) for the city charging tests."""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import pandas as pd

from tollcli.simulate.drive import SimConfig
from tollcli.simulate.route import along_route, straight
from tollcli.simulate.run import write_drive

GEO_DIR = Path(__file__).resolve().parents[1] / "geoobjects"
CITY = GEO_DIR / "example-city.geojson"
GOTHENBURG = GEO_DIR / "example-gothenburg.toml"
ZONE_TARIFF = GEO_DIR / "example-zone.toml"
CENTRE = (57.7070, 11.9670)
SPEED_MPS = 13.89
#: seconds from a leg's start (3 km out) to its first cordon crossing (1.5 km out)
TO_CORDON_S = 1500.0 / SPEED_MPS


def point(bearing_deg: float, r_m: float, offset_m: float = 0.0) -> tuple[float, float]:
    """(lat, lon) r metres out from the centre along a bearing, offset metres to the left of the outward direction
    (as samples/make_city.py draws the roads)."""
    b = math.radians(bearing_deg)
    e = r_m * math.sin(b) - offset_m * math.cos(b)
    n = r_m * math.cos(b) + offset_m * math.sin(b)
    return CENTRE[0] + n / 111_300.0, CENTRE[1] + e / (111_300.0 * math.cos(math.radians(CENTRE[0])))


def leg(out: Path, bearing_deg: float, start_utc: dt.datetime, duration_s: float, seed: int, **config) -> Path:
    """A straight drive from 3 km out on the radial at ``bearing_deg`` towards the centre (and on through it)."""
    lat, lon = point(bearing_deg, 3000.0)
    traj = straight(lat, lon, (bearing_deg + 180.0) % 360.0, SPEED_MPS, duration_s, 1.0)
    write_drive(traj, SimConfig(env=config.pop("env", "urban"), seed=seed, start_utc=start_utc, **config), str(out))
    return out


def route_leg(out: Path, points: list[tuple[float, float]], start_utc: dt.datetime, seed: int, **config) -> Path:
    """A drive along a polyline of (lat, lon) points (a U-turn where it doubles back)."""
    import shapely

    line = shapely.LineString([(lon, lat) for lat, lon in points])
    traj = along_route([line], SPEED_MPS, 1.0, None)
    write_drive(traj, SimConfig(env=config.pop("env", "urban"), seed=seed, start_utc=start_utc, **config), str(out))
    return out


#: the example weekday (Tuesday 3 March 2026, CET = UTC+1): (bearing of the radial entered, local time of the first
#: crossing, seconds driven) — 9 crossings: G1 and G5 at 06:35 and 06:38:36, G5 at 07:20 (three within 60 minutes),
#: then G2 08:40, G4 10:00, G6 12:00, G7 15:10, G8 16:30, G1 17:45
WEEKDAY = dt.date(2026, 3, 3)
LEGS = ((0.0, "06:35:00", 450.0), (180.0, "07:20:00", 200.0), (45.0, "08:40:00", 200.0), (135.0, "10:00:00", 200.0),
        (225.0, "12:00:00", 200.0), (270.0, "15:10:00", 200.0), (315.0, "16:30:00", 200.0), (0.0, "17:45:00", 200.0))  # fmt: skip


def day_legs(folder: Path, day: dt.date = WEEKDAY, utc_offset_h: int = 1, env: str = "rural") -> list[Path]:
    """The example weekday's legs, each its own folder (drive.nmea, truth.csv): streets of the rural environment (the
    suburbs' — the urban canyon's availability is what tests/test_city_outage.py and docs/city.md measure)."""
    out = []
    for k, (bearing, local, duration) in enumerate(LEGS):
        hh, mm, ss = (int(v) for v in local.split(":"))
        cross = dt.datetime(day.year, day.month, day.day, hh, mm, ss, tzinfo=dt.UTC) - dt.timedelta(hours=utc_offset_h)
        out.append(leg(folder / f"leg{k + 1}", bearing, cross - dt.timedelta(seconds=round(TO_CORDON_S)), duration, seed=100 + k, env=env))
    return out


def join_logs(legs: list[Path], out: Path, name: str = "drive.nmea") -> Path:
    """The legs' logs as one log of the day (and their truths as one truth beside it, ``truth.csv``)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text("".join((p / name).read_text() for p in legs))
    pd.concat([pd.read_csv(p / "truth.csv") for p in legs]).to_csv(out / "truth.csv", index=False)
    return out / name


def nmea_checksum(body: str) -> str:
    value = 0
    for ch in body:
        value ^= ord(ch)
    return f"{value:02X}"


def redate_nmea(text: str, day: dt.date) -> str:
    """An NMEA log with every RMC and ZDA date set to ``day`` (checksums made again): the same drive on another date."""
    out = []
    for line in text.splitlines(keepends=True):
        core = line.rstrip("\r\n")
        if core.startswith("$") and "*" in core and core[3:6] in ("RMC", "ZDA"):
            fields = core[1 : core.index("*")].split(",")
            if core[3:6] == "RMC" and len(fields) > 9 and fields[9]:
                fields[9] = day.strftime("%d%m%y")
            elif core[3:6] == "ZDA" and len(fields) > 4 and fields[2]:
                fields[2:5] = [f"{day.day:02d}", f"{day.month:02d}", f"{day.year:04d}"]
            body = ",".join(fields)
            line = f"${body}*{nmea_checksum(body)}" + line[len(core):]
        out.append(line)
    return "".join(out)


def invoice(path: Path) -> dict:
    return json.loads(Path(path).read_text())
