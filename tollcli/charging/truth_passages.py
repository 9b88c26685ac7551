"""The truth an audit compares invoices with: the passages really driven, one row per passage.

A truth is either a list of geo-object ids (a JSON array, or one id per line; an id listed twice is two
passages, times unknown) or a reference trajectory (CSV, Parquet or GeoJSON). A trajectory's points inside a
geo-object (and, on a carriageway, travelling its way) are grouped into passages by the rule the recognition
uses (:func:`recognition.passage_gaps_s`: a new passage after ``passage_gap_s`` without a point inside), so a
road driven twice is two passages, each with its entry and exit time.

Accepted trajectory columns (case-insensitive): latitude ``lat_deg``, ``latdeg``, ``lat``, ``latitude``,
``latitudedegrees``; longitude ``lon_deg``, ``lngdeg``, ``lon``, ``lng``, ``longitude``, ``longitudedegrees``;
time ``time_utc``, ``time``, ``timestamp`` (ISO 8601), ``unixtimemillis`` (GSDC 2022, ms since 1970) or
``millissincegpsepoch`` (GSDC 2021, GPS ms since 1980-01-06); course ``heading_deg``, ``course_deg``,
``bearingdegrees``. A libRSF ground-truth file (smartLoc ``point3`` lines, ECEF) is read as its trajectory.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError

LAT_COLUMNS = ("lat_deg", "latdeg", "lat", "latitude", "latitudedegrees")
LON_COLUMNS = ("lon_deg", "lngdeg", "lon", "lng", "longitude", "longitudedegrees")
TIME_COLUMNS = ("time_utc", "time", "timestamp")
UNIX_MS_COLUMNS = ("unixtimemillis",)
GPS_MS_COLUMNS = ("millissincegpsepoch",)
COURSE_COLUMNS = ("heading_deg", "course_deg", "bearingdegrees")
PASSAGE_COLUMNS = ("geoobject", "entry_utc", "exit_utc")


def read_truth_text(path: str) -> str:
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.read()
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: unreadable ({exc})") from None


def is_id_list(path: str) -> bool:
    """Whether a truth file is a list of ids rather than a trajectory (a missing file counts as a list: the reader
    reports it)."""
    if path.lower().endswith((".parquet", ".csv", ".geojson")):
        return False
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096).lstrip()
    except (OSError, UnicodeDecodeError):
        return True
    if head.startswith(("point3 ", "pseudorange3 ", "odom3 ")):
        return False  # a libRSF ground truth
    first = head.splitlines()[0] if head else ""
    return head.startswith("[") or ("lat" not in first.lower() and "," not in first and not head.startswith("{"))


def passages_from_ids(ids) -> pd.DataFrame:
    """One passage per listed id (repeated ids: repeated passages), times unknown."""
    ids = [str(i) for i in ids]
    return pd.DataFrame({"geoobject": pd.Series(ids, dtype=object), "entry_utc": pd.Series(pd.NaT, index=range(len(ids)), dtype="datetime64[ns, UTC]"),
                         "exit_utc": pd.Series(pd.NaT, index=range(len(ids)), dtype="datetime64[ns, UTC]")})  # fmt: skip


def truth_trajectory(path: str, start_time: str | None = None) -> pd.DataFrame:
    """A trajectory as ``lat_deg``, ``lon_deg``, ``time_utc`` (NaT when it has none) and ``course_deg`` if given.

    ``start_time`` (ISO 8601): when a trajectory whose times are seconds from its start (libRSF ``point3``) began,
    as the invoices it is compared with were placed (their ``parameters.start_time``); None leaves it at 1970-01-01.
    """
    if path.lower().endswith(".parquet"):
        from tollcli.io.sources import read_table

        return _columns(read_table(path), path)
    text = read_truth_text(path).strip()
    if text.startswith("{"):
        return _geojson(text, path)
    if text.startswith(("point3 ", "pseudorange3 ", "odom3 ")):
        from tollcli.readers.librsf import librsf_truth

        from tollcli.readers.librsf import LIBRSF_T0

        points = librsf_truth(path)[["lat_deg", "lon_deg", "time_utc"]]
        if start_time is not None:
            points["time_utc"] = points["time_utc"] + (pd.Timestamp(start_time).tz_convert("UTC") - LIBRSF_T0)
        return points
    from io import StringIO

    try:
        table = pd.read_csv(StringIO(text))
    except ValueError as exc:
        raise DataError(f"{path}: not a readable trajectory ({str(exc).splitlines()[0]})") from None
    return _columns(table, path)


def _pick(table: pd.DataFrame, names: tuple[str, ...]):
    return next((c for c in table.columns if str(c).lower() in names), None)


def _columns(table: pd.DataFrame, path: str) -> pd.DataFrame:
    lat, lon = _pick(table, LAT_COLUMNS), _pick(table, LON_COLUMNS)
    if lat is None or lon is None:
        raise DataError(f"{path}: a truth trajectory needs latitude and longitude columns "
                        f"(latitude: {', '.join(LAT_COLUMNS)}; longitude: {', '.join(LON_COLUMNS)}; any case)")  # fmt: skip
    out = pd.DataFrame({"lat_deg": pd.to_numeric(table[lat], errors="coerce").to_numpy(float),
                        "lon_deg": pd.to_numeric(table[lon], errors="coerce").to_numpy(float)})  # fmt: skip
    out["time_utc"] = _times(table)
    course = _pick(table, COURSE_COLUMNS)
    if course is not None:
        out["course_deg"] = pd.to_numeric(table[course], errors="coerce").to_numpy(float)
    return out


def _times(table: pd.DataFrame) -> pd.Series:
    column = _pick(table, TIME_COLUMNS)
    if column is not None:
        return pd.to_datetime(table[column], utc=True, errors="coerce").reset_index(drop=True)
    column = _pick(table, UNIX_MS_COLUMNS)
    if column is not None:
        return pd.to_datetime(pd.to_numeric(table[column], errors="coerce"), unit="ms", utc=True).reset_index(drop=True)
    column = _pick(table, GPS_MS_COLUMNS)
    if column is not None:
        from tollcli.readers.gps_time import gps_millis_to_utc

        millis = pd.to_numeric(table[column], errors="coerce").to_numpy(float)
        utc = gps_millis_to_utc(np.nan_to_num(millis).astype(np.int64)).astype("datetime64[ns]")
        return pd.Series(pd.DatetimeIndex(np.where(np.isfinite(millis), utc, np.datetime64("NaT"))).tz_localize("UTC"))
    return pd.Series(pd.NaT, index=range(len(table)), dtype="datetime64[ns, UTC]")


def _geojson(text: str, path: str) -> pd.DataFrame:
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise DataError(f"{path}: not valid GeoJSON ({exc})") from None
    coords, times = [], []
    for feature in doc.get("features", []):
        geom = feature.get("geometry") or {}
        props = feature.get("properties") or {}
        if geom.get("type") == "Point":
            coords.append(geom["coordinates"][:2])
            times.append(next((props[k] for k in TIME_COLUMNS if k in props), None))
        elif geom.get("type") == "LineString":
            coords.extend(c[:2] for c in geom["coordinates"])
            times.extend([None] * len(geom["coordinates"]))
    lon = np.array([c[0] for c in coords], float)
    lat = np.array([c[1] for c in coords], float)
    return pd.DataFrame({"lat_deg": lat, "lon_deg": lon, "time_utc": pd.to_datetime(pd.Series(times, dtype=object), utc=True, errors="coerce")})


def track_deg(points: pd.DataFrame) -> np.ndarray:
    """The direction of travel at each point of a trajectory (towards the next point; the last repeats), degrees
    from north; NaN where the vehicle does not move."""
    lat, lon = np.radians(points["lat_deg"].to_numpy(float)), np.radians(points["lon_deg"].to_numpy(float))
    if lat.size < 2:
        return np.full(lat.size, np.nan)
    dn, de = np.diff(lat), np.diff(lon) * np.cos((lat[1:] + lat[:-1]) / 2)
    track = np.where(np.hypot(dn, de) > 0, np.degrees(np.arctan2(de, dn)) % 360.0, np.nan)
    return np.append(track, track[-1])


def passages_from_trajectory(points: pd.DataFrame, geo) -> pd.DataFrame:
    """The passages a trajectory drove: per geo-object, its inside points (in the direction of travel on a
    carriageway) split where no point was inside for longer than the recognition's passage gap. Without times,
    a point outside between two inside ones splits."""
    from tollcli.charging.recognition import candidate_pairs, passage_gaps_s

    points = points[np.isfinite(points["lat_deg"].to_numpy(float)) & np.isfinite(points["lon_deg"].to_numpy(float))]
    points = points.reset_index(drop=True)
    if points.empty:
        return passages_from_ids([])
    rows, obj, px, py = candidate_pairs(points, geo)
    directed = geo.directed()[obj]
    if directed.any():  # a carriageway is driven only in its direction of travel (carriageways.py)
        from tollcli.geoobjects.carriageways import direction_check

        course = points["course_deg"].to_numpy(float) if "course_deg" in points else track_deg(points)
        ok = direction_check(geo.axes[obj[directed]], px[directed], py[directed], course[rows[directed]],
                             np.full(int(directed.sum()), 1e9)) == ""  # a trajectory: its course is the truth  # fmt: skip
        keep = ~directed
        keep[directed] = ok
        rows, obj = rows[keep], obj[keep]
    if rows.size == 0:
        return passages_from_ids([])
    times = points["time_utc"]
    timed = bool(times.notna().all())
    order = np.lexsort((rows, obj))
    rows, obj = rows[order], obj[order]
    new = np.ones(rows.size, bool)
    if timed:
        t_s = (times.to_numpy("datetime64[ns]").astype("int64") / 1e9)[rows]
        new[1:] = (obj[1:] != obj[:-1]) | (np.diff(t_s) > passage_gaps_s(geo)[obj[1:]])
    else:
        new[1:] = (obj[1:] != obj[:-1]) | (np.diff(rows) > 1)
    start, end = np.flatnonzero(new), np.append(np.flatnonzero(new)[1:], rows.size) - 1
    out = pd.DataFrame({"geoobject": geo.ids[obj[start]].astype(str).astype(object),
                        "entry_utc": times.to_numpy()[rows[start]] if timed else pd.NaT,
                        "exit_utc": times.to_numpy()[rows[end]] if timed else pd.NaT})  # fmt: skip
    for c in ("entry_utc", "exit_utc"):
        out[c] = pd.to_datetime(out[c], utc=True)
    return out.sort_values(["entry_utc", "geoobject"], kind="stable").reset_index(drop=True) if timed else out


def truth_passages(path: str, geo, start_time: str | None = None) -> pd.DataFrame:
    """The passages really driven (``geoobject``, ``entry_utc``, ``exit_utc``) from a truth file (``start_time``: see
    :func:`truth_trajectory`)."""
    if is_id_list(path):
        text = read_truth_text(path).strip()
        if text.startswith("["):
            try:
                ids = [str(i) for i in json.loads(text)]
            except (ValueError, TypeError) as exc:
                raise DataError(f"{path}: not a JSON list of geo-object ids ({exc})") from None
        else:
            ids = [line.strip() for line in text.splitlines() if line.strip() and not line.startswith("#")]
        unknown = sorted(set(ids) - {str(g) for g in geo.ids}) if geo is not None else []
        if unknown:
            raise DataError(f"{path}: geo-objects {', '.join(unknown[:5])} are not in the geo-objects given")
        return passages_from_ids(ids)
    if geo is None:
        raise UsageError("a truth trajectory needs --geo to know where the geo-objects are")
    return passages_from_trajectory(truth_trajectory(path, start_time), geo)
