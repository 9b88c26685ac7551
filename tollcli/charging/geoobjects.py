"""Geo-objects: constant-HAL buffers around tolled road segments (paper 001 §II; thesis §3.4).

A road network is a GeoJSON FeatureCollection of LineStrings (centre lines) with
properties ``id``, ``name``, ``road_class``, optional ``hal_m``, optional
``direction`` and ``tolled`` (default true). Non-tolled roads only bound HAL.

:func:`build_geoobjects` works in a metric CRS (the local UTM zone picked from
the data) and, for every tolled segment:

1. HAL = min(HAL_max, its own ``hal_m`` if given, ½ · distance to the nearest road it
   is not connected to). "Connected" means touching within ``connect_tol_m``
   (a junction); connected roads meet the segment by construction and would
   otherwise force HAL to zero.
2. Ends that meet another road are trimmed by ``trim_factor · HAL`` so that the
   buffer does not reach into the roads leaving the junction.
3. The geo-object is the centre line buffered by HAL (round caps): a position
   inside it, valid with HPL = HAL, is within HAL of the tolled road.

The output is GeoJSON in WGS-84 (RFC 7946) with the metric CRS used recorded
per feature (``crs_metric``), so recognition can project positions the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.ops import substring

from tollcli.errors import DataError
from tollcli.spatial import feature_geometry, metric_crs, project, read_features

HAL_MAX_M = 50.0
CONNECT_TOL_M = 1.0
TRIM_FACTOR = 2.0


@dataclass
class Finding:
    """One problem of a geo-object file, tied to a feature."""

    feature: str  # id, or "#<index>" when the feature has none
    problem: str

    def __str__(self) -> str:
        return f"{self.feature}: {self.problem}"


def _feature_id(feature, index: int) -> str:
    props = feature.get("properties") if isinstance(feature, dict) else None
    fid = props.get("id") if isinstance(props, dict) else None
    return str(fid) if fid not in (None, "") else f"#{index}"


def _roads(features: list[dict], path: str):
    """(ids, properties, WGS-84 lines) of the road features; DataError on unusable ones."""
    ids, props, lines = [], [], []
    for i, feature in enumerate(features):
        fid = _feature_id(feature, i)
        geom, why = feature_geometry(feature)
        if geom is None:
            raise DataError(f"{path}: feature {fid}: {why}")
        if geom.geom_type == "MultiLineString" and len(geom.geoms) == 1:
            geom = geom.geoms[0]
        if geom.geom_type != "LineString" or geom.is_empty:
            raise DataError(f"{path}: feature {fid}: a road must be a LineString, got {geom.geom_type}")
        if geom.length == 0:
            raise DataError(f"{path}: feature {fid}: a road of zero length (all its points are the same)")
        lon, lat = np.asarray(geom.coords)[:, 0], np.asarray(geom.coords)[:, 1]
        if (np.abs(lon) > 180).any() or (np.abs(lat) > 90).any():
            raise DataError(f"{path}: feature {fid}: coordinates are not longitude/latitude degrees")
        ids.append(fid)
        props.append(dict(feature.get("properties") or {}) if isinstance(feature.get("properties"), dict) else {})
        lines.append(geom)
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise DataError(f"{path}: duplicate road ids {', '.join(dup)}")
    if not lines:
        raise DataError(f"{path}: no roads")
    return ids, props, lines


def build_geoobjects(path: str, hal_max_m: float = HAL_MAX_M, connect_tol_m: float = CONNECT_TOL_M,
                     trim_factor: float = TRIM_FACTOR) -> dict:  # fmt: skip
    """A roads file → a GeoJSON FeatureCollection of geo-objects (dict, WGS-84)."""
    ids, props, lines = _roads(read_features(path), path)
    crs = metric_crs(lines)
    metric = project(lines, crs)
    tolled = np.array([p.get("tolled", True) is not False for p in props])
    if not tolled.any():
        raise DataError(f"{path}: no tolled road (every feature has tolled: false)")
    tree = shapely.STRtree(metric)
    # every pair within reach of a HAL decision: 2·HAL_max around each tolled segment
    left, right = tree.query(metric[tolled], predicate="dwithin", distance=2 * hal_max_m)
    tolled_idx = np.flatnonzero(tolled)
    left = tolled_idx[left]
    other = left != right
    left, right = left[other], right[other]
    dist = shapely.distance(metric[left], metric[right])
    connected = dist <= connect_tol_m
    hal = np.full(len(metric), hal_max_m)
    own = np.array([float(p["hal_m"]) if p.get("hal_m") not in (None, "") else np.inf for p in props])
    hal = np.minimum(hal, own)
    np.minimum.at(hal, left[~connected], dist[~connected] / 2.0)
    cores = []
    for i in tolled_idx:  # trimming needs shapely's substring, which works on one line at a time
        line = metric[i]
        touching = right[(left == i) & connected]
        ends = shapely.points(np.asarray([line.coords[0], line.coords[-1]]))
        near_end = (shapely.distance(ends[:, None], metric[touching][None, :]) <= connect_tol_m).any(axis=1) if touching.size else (False, False)
        start_cut, end_cut = (trim_factor * hal[i] if near else 0.0 for near in near_end)
        if start_cut + end_cut >= line.length:
            raise DataError(f"{path}: feature {ids[i]}: too short ({line.length:.1f} m) to trim {start_cut + end_cut:.1f} m at its junctions")
        cores.append(substring(line, start_cut, line.length - end_cut))
    cores = np.asarray(cores, dtype=object)
    polygons = project(shapely.buffer(cores, hal[tolled_idx], quad_segs=16), crs, inverse=True)
    features = []
    for k, i in enumerate(tolled_idx):
        properties = {
            "id": ids[i], "name": props[i].get("name", ""), "road_class": props[i].get("road_class", ""),
            "direction": props[i].get("direction"), "hal_m": round(float(hal[i]), 3), "crs_metric": crs,
            "length_m": round(cores[k].length, 1),
        }  # fmt: skip
        features.append({"type": "Feature", "properties": properties, "geometry": shapely.geometry.mapping(polygons[k])})
    return {"type": "FeatureCollection", "features": features}


def _crs_problem(crs, seen: dict) -> str:
    """Why a feature's ``crs_metric`` cannot be used ('' when absent or a known projected CRS in metres)."""
    if crs is None:
        return ""
    if crs not in seen:
        from pyproj import CRS
        from pyproj.exceptions import CRSError

        try:
            parsed = CRS.from_user_input(crs)
            metres = parsed.is_projected and all(a.unit_name in ("metre", "meter") for a in parsed.axis_info)
            seen[crs] = "" if metres else f"crs_metric {crs!r} is not a projected CRS in metres"
        except (CRSError, TypeError, ValueError):
            seen[crs] = f"crs_metric {crs!r} is not a known coordinate reference system"
    return seen[crs]


def check_geoobjects(path: str, hal_min_m: float = 5.0) -> list[Finding]:
    """Problems of a geo-object file, each tied to a feature id (empty list: the file is usable)."""
    findings: list[Finding] = []
    crs_seen: dict = {}
    features = read_features(path)
    ids: list[str] = []
    polys = []
    for i, feature in enumerate(features):
        fid = _feature_id(feature, i)
        props = feature.get("properties") if isinstance(feature, dict) and isinstance(feature.get("properties"), dict) else {}
        if fid.startswith("#"):
            findings.append(Finding(fid, "missing id"))
        if fid in ids:
            findings.append(Finding(fid, "duplicate id"))
        ids.append(fid)
        geom, why = feature_geometry(feature)
        if geom is None:
            findings.append(Finding(fid, why))
            polys.append(None)
            continue
        if geom.is_empty or geom.geom_type not in ("Polygon", "MultiPolygon"):
            findings.append(Finding(fid, f"geometry must be a non-empty Polygon, got {geom.geom_type}{' (empty)' if geom.is_empty else ''}"))
            polys.append(None)
            continue
        bounds = np.asarray(geom.bounds)
        if (np.abs(bounds[[0, 2]]) > 180).any() or (np.abs(bounds[[1, 3]]) > 90).any():
            findings.append(Finding(fid, "coordinates are not WGS-84 longitude/latitude (wrong CRS?)"))
            polys.append(None)
            continue
        if not geom.is_valid:
            findings.append(Finding(fid, f"invalid geometry: {shapely.is_valid_reason(geom)}"))
        crs_problem = _crs_problem(props.get("crs_metric"), crs_seen)
        if crs_problem:
            findings.append(Finding(fid, crs_problem))
        hal = props.get("hal_m")
        try:
            hal_value = float(hal)
        except (TypeError, ValueError):
            findings.append(Finding(fid, f"hal_m missing or not a number ({hal!r})"))
        else:
            if not hal_value >= hal_min_m:
                findings.append(Finding(fid, f"hal_m {hal_value:g} m below the minimum {hal_min_m:g} m"))
        polys.append(geom if geom.is_valid else None)
    usable = [(fid, p) for fid, p in zip(ids, polys) if p is not None]
    if len(usable) > 1:
        crs = metric_crs([p for _, p in usable])
        metric = project([p for _, p in usable], crs)
        a, b = shapely.STRtree(metric).query(metric, predicate="intersects")
        for i, j in zip(a, b):
            if i < j:
                area = shapely.intersection(metric[i], metric[j]).area
                if area > 1.0:
                    findings.append(Finding(usable[i][0], f"overlaps {usable[j][0]} ({area:.0f} m²)"))
    return findings
