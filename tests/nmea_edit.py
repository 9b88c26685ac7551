"""Edit NMEA sentences as a receiver (or a forger) would write them: fields changed, checksum made good."""

from __future__ import annotations

from collections.abc import Callable
from functools import reduce


def checksum(body: str) -> str:
    """The two hex digits of an NMEA sentence's body (between '$' and '*')."""
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def edit_fields(line: str, edit: Callable[[list[str]], None]) -> str:
    """``line`` with ``edit`` applied to its comma-separated fields (field 0 is the talker and type), checksummed."""
    if not line.startswith("$") or "*" not in line:
        return line
    fields = line[1 : line.rfind("*")].split(",")
    edit(fields)
    body = ",".join(fields)
    return f"${body}*{checksum(body)}"


def sentence_type(line: str) -> str:
    """'GGA', 'RMC', … of a sentence ('' for anything else)."""
    return line[3:6] if line.startswith("$") and len(line) > 6 else ""


def time_field_s(line: str) -> float | None:
    """Seconds of the day of a sentence that carries a time (GGA, RMC, GST, GRS; None for others)."""
    kind = sentence_type(line)
    if kind not in ("GGA", "RMC", "GST", "GRS", "GBS"):
        return None
    hhmmss = line.split(",")[1]
    if len(hhmmss) < 6:
        return None
    return int(hhmmss[:2]) * 3600 + int(hhmmss[2:4]) * 60 + float(hhmmss[4:])


def scale_speed(line: str, factor: float) -> str:
    """RMC speed (knots, field 7) and VTG speeds (knots 5, km/h 7) times ``factor``."""
    kind = sentence_type(line)

    def edit(f: list[str]) -> None:
        for i in {"RMC": (7,), "VTG": (5, 7)}.get(kind, ()):
            if f[i]:
                f[i] = f"{float(f[i]) * factor:.3f}"

    return edit_fields(line, edit) if kind in ("RMC", "VTG") else line


def shift_position(line: str, north_m: float, east_m: float) -> str:
    """GGA/RMC/GLL latitude and longitude moved by (north, east) metres."""
    import math

    kind = sentence_type(line)
    at = {"GGA": 2, "RMC": 3, "GLL": 1}.get(kind)
    if at is None:
        return line

    def edit(f: list[str]) -> None:
        if not f[at] or not f[at + 2]:
            return
        lat = (int(f[at][:2]) + float(f[at][2:]) / 60.0) * (1 if f[at + 1] == "N" else -1)
        lon = (int(f[at + 2][:3]) + float(f[at + 2][3:]) / 60.0) * (1 if f[at + 3] == "E" else -1)
        lat += north_m / 111_132.0
        lon += east_m / (111_320.0 * math.cos(math.radians(lat)))
        a, b = abs(lat), abs(lon)
        f[at] = f"{int(a):02d}{(a - int(a)) * 60:010.7f}"
        f[at + 1] = "N" if lat >= 0 else "S"
        f[at + 2] = f"{int(b):03d}{(b - int(b)) * 60:010.7f}"
        f[at + 3] = "E" if lon >= 0 else "W"

    return edit_fields(line, edit)


def edit_during(lines: list[str], start_s: float, end_s: float, edit: Callable[[str], str]) -> list[str]:
    """``edit`` applied to every sentence of the epochs whose time of day is in [start_s, end_s) (a sentence without a
    time belongs to the epoch of the last timed one before it)."""
    out, inside = [], False
    for line in lines:
        t = time_field_s(line)
        if t is not None:
            inside = start_s <= t < end_s
        out.append(edit(line) if inside else line)
    return out
