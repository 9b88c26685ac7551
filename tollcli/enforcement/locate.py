"""Where is the vehicle: its last trusted position (and the last of any kind), or the position at a time.

The vehicle id: ``--vehicle`` for a single log, else a ``# vehicle: ID`` line in the log's
comment header, else the file name without folders and extensions.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pandas as pd

#: what a located position reports
COLUMNS = ("vehicle", "log", "which", "time_utc", "lat_deg", "lon_deg", "raim_status", "hpl_m", "hal_m",
           "speed_mps", "course_deg", "line")  # fmt: skip
TRUSTED = ("valid", "excluded_valid")


#: suffixes a log's file name ends with that are not part of the vehicle id: a compression, then a log kind
COMPRESSION_SUFFIXES = (".gz", ".bz2", ".xz", ".zst")
LOG_FILE_SUFFIXES = (".nmea", ".log", ".txt", ".csv", ".ubx", ".obs", ".rnx", ".dat", ".bin", ".json", ".parquet")
_RINEX_OBS = re.compile(r"\.\d\d[oO]$")


_QUALIFIER = re.compile(r"^(.+?)\.[A-Za-z][^.]*$")


def vehicle_from_path(path: str) -> str:
    """The vehicle id a log's file name gives: its name without folders, its log suffixes and the qualifiers
    after a dot that start with a letter (``TRK-042.nmea.gz`` → ``TRK-042``; ``TRK-5.morning.nmea`` → ``TRK-5``:
    the qualifier names the log). A dot followed by a digit is part of the id (``ublox-zed-f9p_hpg1.11.log`` →
    ``ublox-zed-f9p_hpg1.11``)."""
    name = os.path.basename(path)
    for suffixes in (COMPRESSION_SUFFIXES, LOG_FILE_SUFFIXES):
        lower = name.lower()
        ext = next((s for s in suffixes if lower.endswith(s) and len(name) > len(s)), None)
        if ext is not None:
            name = name[: -len(ext)]
        elif suffixes is LOG_FILE_SUFFIXES and _RINEX_OBS.search(name):
            name = name[:-4]
    while (m := _QUALIFIER.match(name)) is not None:
        name = m.group(1)
    return name


#: ``# vehicle: ID`` (or ``vehicle id``, ``vehicle_id``, ``=``): the id is the whole rest of that line, trimmed
_HEADER_VEHICLE = re.compile(rb"^#[ \t]*vehicle(?:[ _-]?id)?[ \t]*[:=]([^\r\n]*)", re.IGNORECASE | re.MULTILINE)
#: the longest vehicle id (characters): a plate, a VIN (17), a fleet's own numbering fit many times over
VEHICLE_ID_MAX_CHARS = 64


def vehicle_id_problem(vehicle: str) -> str | None:
    """Why ``vehicle`` cannot be a vehicle id (None: it can): control characters (a tab, a line end, NUL) or more than
    :data:`VEHICLE_ID_MAX_CHARS` characters (its invoice folder's name, percent-encoded, must fit a file system)."""
    if any(ord(c) < 0x20 or 0x7F <= ord(c) < 0xA0 for c in vehicle):
        return f"vehicle id {vehicle!r} has control characters"
    if len(vehicle) > VEHICLE_ID_MAX_CHARS:
        return f"vehicle id {vehicle[:20]!r}… has {len(vehicle)} characters, more than {VEHICLE_ID_MAX_CHARS}"
    return None


def vehicle_from_log(path: str) -> str | None:
    """A vehicle id written in the log's comment header (``# vehicle: TRK-042``), if any (first 4 KiB)."""
    if path == "-":
        return None
    from tollcli.io.sources import open_binary

    try:
        with open_binary(path) as fh:
            head = fh.read(4096)
    except Exception:  # noqa: BLE001 - the reader will report the file properly
        return None
    return vehicle_in_head(head)


def vehicle_in_head(head: bytes) -> str | None:
    """The vehicle id of a ``# vehicle: ID`` comment line in a log's first bytes, if any: the whole rest of the line,
    blanks inside kept (``FLEET 1`` and ``FLEET 2`` are two vehicles), around it trimmed; an empty one is none."""
    match = _HEADER_VEHICLE.search(head)
    if not match:
        return None
    vehicle = match.group(1).decode("utf-8", "replace").strip(" \t")
    return vehicle or None


def separate_simultaneous(vehicles: list[str], named_by_file: list[bool], logs: list[str],
                          spans: list[tuple | None]) -> tuple[list[str], list[str]]:
    """Vehicle ids with logs that cannot be one vehicle told apart, and what was done (one line each).

    Logs whose ids come from their file names (``day1/TRK-042.nmea``, ``day2/TRK-042.nmea``) are one
    vehicle's — unless their time spans overlap: one vehicle does not record two logs at once
    (``urban/drive.nmea``, ``rural/drive.nmea`` of the same morning). Those get their folder's name in
    front (``urban/drive``). Ids from a log header or ``--vehicle`` are kept as given.
    """
    out, notes = list(vehicles), []
    by_id: dict[str, list[int]] = {}
    for i, (vid, by_file) in enumerate(zip(vehicles, named_by_file)):
        if by_file and spans[i] is not None:
            by_id.setdefault(vid, []).append(i)
    for vid, members in by_id.items():
        clash = {i for i in members for j in members if i != j
                 and spans[i][0] <= spans[j][1] and spans[j][0] <= spans[i][1]}  # fmt: skip
        for i in sorted(clash):
            folder = os.path.basename(os.path.dirname(os.path.abspath(logs[i]))) or "."
            out[i] = f"{folder}/{vid}"
        if clash:
            notes.append(f"{len(clash)} logs named {vid!r} were recorded at the same time: not one vehicle, "
                         f"told apart by their folders ({', '.join(sorted(out[i] for i in clash))})")  # fmt: skip
    return out, notes


def locate_in(table: pd.DataFrame, at_utc: pd.Timestamp | None = None) -> dict[str, pd.Series | None]:
    """The last trusted row and the last row with a position (at or before ``at_utc`` when given)."""
    t = table
    if at_utc is not None and "time_utc" in t:
        t = t[t["time_utc"].notna() & (t["time_utc"] <= at_utc)]
    lat = t["raim_lat_deg"] if "raim_lat_deg" in t else t["lat_deg"]
    has_pos = np.isfinite(t["lat_deg"].to_numpy(float)) & np.isfinite(lat.to_numpy(float))
    trusted = has_pos & t["raim_status"].astype(str).isin(TRUSTED).to_numpy()
    last_any = t[has_pos].iloc[-1] if has_pos.any() else None
    last_trusted = t[trusted].iloc[-1] if trusted.any() else None
    return {"trusted": last_trusted, "any": last_any}


def located_rows(vehicle: str, log: str, found: dict[str, pd.Series | None]) -> list[dict]:
    """Rows of the locate table: the trusted position, and the last of any kind when it is a different epoch."""
    rows = []
    for which in ("trusted", "any"):
        row = found[which]
        if row is None:
            continue
        if which == "any" and found["trusted"] is not None and row.name == found["trusted"].name:
            continue
        use_raim = which == "trusted" and "raim_lat_deg" in row
        rows.append({
            "vehicle": vehicle, "log": log, "which": "last_trusted" if which == "trusted" else "last_any",
            "time_utc": row.get("time_utc"),
            "lat_deg": float(row["raim_lat_deg"] if use_raim else row["lat_deg"]),
            "lon_deg": float(row["raim_lon_deg"] if use_raim else row["lon_deg"]),
            "raim_status": str(row.get("raim_status", "")), "hpl_m": _f(row.get("hpl_m")), "hal_m": _f(row.get("hal_m")),
            "speed_mps": _f(row.get("speed_mps")), "course_deg": _f(row.get("course_deg")),
            "line": int(row["line"]) if "line" in row and pd.notna(row["line"]) else None,
        })  # fmt: skip
    return rows


def _f(v):
    return None if v is None or pd.isna(v) else float(v)


def latest_per_vehicle(rows: list[dict]) -> list[dict]:
    """Across several logs of one vehicle, keep the rows of the latest trusted and latest any."""
    best: dict[tuple[str, str], dict] = {}
    for r in rows:
        key = (r["vehicle"], r["which"])
        t = r["time_utc"]
        if key not in best or (pd.notna(t) and (pd.isna(best[key]["time_utc"]) or t > best[key]["time_utc"])):
            best[key] = r
    out = [best[k] for k in sorted(best)]
    # drop a last_any that is older than (or the same as) the vehicle's last trusted position
    trusted = {v: r for (v, w), r in best.items() if w == "last_trusted"}
    return [r for r in out if not (r["which"] == "last_any" and r["vehicle"] in trusted
                                   and pd.notna(r["time_utc"]) and r["time_utc"] <= trusted[r["vehicle"]]["time_utc"])]  # fmt: skip
