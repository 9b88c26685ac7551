"""GeoJSON features and metric map projections, shared by every room that handles roads or geo-objects.

Reading a FeatureCollection (WGS-84 longitude/latitude, RFC 7946), a feature's
geometry without raising, the metric CRS (UTM zone) of a set of lines, and
WGS-84 ↔ metric transforms (pyproj transformers made once per thread).
"""

from __future__ import annotations

import math
import re
import threading

import numpy as np
import shapely

from tollcli.errors import DataError
from tollcli.io.sources import read_json


def read_features(path: str) -> list[dict]:
    """GeoJSON features of a file, with a clear error for anything else."""
    return features_of(read_json(path, "a GeoJSON file"), path)


def features_of(doc, path: str) -> list[dict]:
    """The features of a parsed GeoJSON document read from ``path`` (DataError: not a WGS-84 FeatureCollection)."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        raise DataError(f"{path}: not a GeoJSON FeatureCollection")
    crs = (doc.get("crs") or {}).get("properties", {}).get("name", "")
    if crs and not any(tag in crs.upper() for tag in ("CRS84", "4326")):
        raise DataError(f"{path}: coordinates must be WGS-84 longitude/latitude (RFC 7946), file declares {crs}")
    return doc["features"]


def feature_geometry(feature) -> tuple[object | None, str]:
    """A feature's shapely geometry, or None and why it cannot be read (never raises)."""
    if not isinstance(feature, dict):
        return None, "not a GeoJSON feature"
    if isinstance(feature.get("geometry"), shapely.Geometry):  # a feature made here, its geometry not yet written out
        return feature["geometry"], ""
    try:
        with np.errstate(invalid="ignore"):
            geom = shapely.geometry.shape(feature.get("geometry") or {})
    except (ValueError, TypeError, AttributeError, KeyError, IndexError, OverflowError, shapely.errors.ShapelyError) as exc:
        return None, f"unreadable geometry ({type(exc).__name__}: {' '.join(str(exc).split())})"  # one line: GEOS ends its messages with a newline
    coords = shapely.get_coordinates(geom)
    if not np.isfinite(coords).all():
        return None, "coordinates must be finite numbers"
    return geom, ""


def feature_geometries(features: list, kind: str) -> np.ndarray:
    """Shapely geometries of GeoJSON features (None where unreadable), the plain ones built in bulk: ``kind``
    ``"Polygon"`` (one ring of ≥ 4 points) or ``"LineString"`` (≥ 2 points); any other feature by
    :func:`feature_geometry`. The same geometries, coordinate for coordinate, as ``feature_geometry`` gives."""
    out = np.full(len(features), None, dtype=object)
    simple, runs = [], []
    for i, f in enumerate(features):
        geom = f.get("geometry") if isinstance(f, dict) else None
        if isinstance(geom, shapely.Geometry):
            out[i] = geom
            continue
        coords = geom.get("coordinates") if isinstance(geom, dict) and geom.get("type") == kind else None
        if kind == "Polygon":
            coords = coords[0] if isinstance(coords, list) and len(coords) == 1 and isinstance(coords[0], list) and len(coords[0]) >= 4 else None
        if isinstance(coords, list) and len(coords) >= 2:
            try:
                run = np.asarray(coords, dtype=float)
            except (TypeError, ValueError, OverflowError):  # (an integer of hundreds of digits)
                run = None
            if run is not None and run.ndim == 2 and run.shape[1] == 2 and np.isfinite(run).all():
                simple.append(i)
                runs.append(run)
                continue
        out[i] = feature_geometry(f)[0]
    if simple:
        lengths = np.array([len(r) for r in runs])
        index = np.repeat(np.arange(len(runs)), lengths)
        with np.errstate(invalid="ignore"):
            if kind == "Polygon":
                built = shapely.polygons(shapely.linearrings(np.concatenate(runs), indices=index))
            else:
                built = shapely.linestrings(np.concatenate(runs), indices=index)
        out[np.array(simple)] = built
    return out


def geojson_coordinates(geoms) -> list:
    """The GeoJSON ``coordinates`` of Polygons and MultiPolygons, built in bulk: the numbers
    ``shapely.geometry.mapping`` gives (as lists where it gives tuples: the same JSON)."""
    geoms = np.asarray(geoms, dtype=object)
    parts, owner = shapely.get_parts(geoms, return_index=True)
    rings, ring_part = shapely.get_rings(parts, return_index=True)
    xy, ring_of = shapely.get_coordinates(rings, return_index=True)
    cut = np.flatnonzero(np.diff(ring_of)) + 1
    ring_lists = [r.tolist() for r in np.split(xy, cut)] if len(xy) else []
    per_part: list[list] = [[] for _ in range(len(parts))]
    for r, part in zip(ring_lists, ring_part.tolist()):
        per_part[part].append(r)
    out: list[list] = [[] for _ in range(len(geoms))]
    for part, g in zip(per_part, owner.tolist()):
        out[g].append(part)
    multi = shapely.get_type_id(geoms) == 6
    return [o if m else o[0] for o, m in zip(out, multi.tolist())]


def feature_collection_text(doc: dict, chunk: int = 2000):
    """``json.dumps(doc, separators=(",", ":"), sort_keys=True) + "\\n"`` of a FeatureCollection, in pieces: the
    features' geometries (GeoJSON dicts, or shapely geometries not yet converted) written ``chunk`` features at a
    time, so a network of any size is never held as one text nor as Python coordinate lists."""
    import json

    dumps = lambda value: json.dumps(value, separators=(",", ":"), sort_keys=True, allow_nan=False)  # noqa: E731  (NaN is not JSON)
    rest = {k: v for k, v in doc.items() if k != "features"}
    keys = sorted([*rest, "features"])
    yield "{"
    for n, key in enumerate(keys):
        yield ("," if n else "") + dumps(key) + ":"
        if key != "features":
            yield dumps(rest[key])
            continue
        features = doc["features"]
        yield "["
        for start in range(0, len(features), chunk):
            block = features[start : start + chunk]
            lazy = [i for i, f in enumerate(block) if isinstance(f.get("geometry"), shapely.Geometry)]
            if lazy:
                geoms = np.array([block[i]["geometry"] for i in lazy], dtype=object)
                block = list(block)
                for i, geom, coords in zip(lazy, geoms, geojson_coordinates(geoms)):
                    block[i] = {**block[i], "geometry": {"type": geom.geom_type, "coordinates": coords}}
            yield ("," if start else "") + ",".join(dumps(f) for f in block)
        yield "]"
    yield "}\n"


def metric_crs(lines_wgs84) -> str:
    """The UTM zone (EPSG code) of the data's centroid."""
    coords = shapely.get_coordinates(np.asarray(lines_wgs84, dtype=object))
    lon, lat = (coords.mean(axis=0) if len(coords) else (0.0, 0.0))
    zone = int(math.floor((lon + 180.0) / 6.0)) % 60 + 1
    return f"EPSG:{32600 + zone if lat >= 0 else 32700 + zone}"


def local_frame(lon_deg: float) -> str:
    """A metric frame for a road near longitude ``lon_deg``: transverse Mercator on the WGS-84 ellipsoid, scale 1 on
    the whole-degree meridian nearest it. Within 0.5° + 100 km of that meridian the scale error stays below 3·10⁻⁴
    (x²/2R²; 7·10⁻⁵ for a road within 0.5°), so lengths, buffers and HAL are ground distances to better than
    0.05 % at any longitude and latitude — unlike one UTM zone for a network wider than the zone."""
    meridian = int(round(float(lon_deg)))
    meridian = ((meridian + 180) % 360) - 180
    return f"+proj=tmerc +lat_0=0 +lon_0={meridian} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _transformer(crs: str, inverse: bool = False):
    """WGS-84 lon/lat → ``crs`` (or back), made once per thread (building one costs milliseconds).

    A :func:`local_frame` on another meridian than one already built is made from that one's PROJ pipeline with the
    meridian changed (0.1 ms instead of the 13 ms of a search of PROJ's database: a drive across a country meets a
    frame per degree of longitude) — the very pipeline the search gives, so the same coordinates to the last bit."""
    from pyproj import Transformer

    cache = _TRANSFORMERS.__dict__.setdefault("by_crs", {})
    key = (crs, inverse)
    if key not in cache:
        from pyproj.exceptions import CRSError

        local = _LOCAL_FRAME.fullmatch(crs)
        template = _TRANSFORMERS.__dict__.setdefault("local_pipelines", {}).get(inverse) if local else None
        if template is not None:
            cache[key] = Transformer.from_pipeline(template.format(meridian=local.group(1)))
            return cache[key]
        src, dst = ("EPSG:4326", crs) if not inverse else (crs, "EPSG:4326")
        try:
            cache[key] = Transformer.from_crs(src, dst, always_xy=True)
        except CRSError:
            raise DataError(f"unknown coordinate reference system {crs!r}") from None
        if local:
            _learn_local_pipeline(cache[key].definition, local.group(1), inverse)
    return cache[key]


#: the frames :func:`local_frame` writes, their meridian captured
_LOCAL_FRAME = re.compile(r"\+proj=tmerc \+lat_0=0 \+lon_0=(-?\d+) \+k=1 \+x_0=0 \+y_0=0 \+ellps=WGS84 \+units=m \+no_defs")


def _learn_local_pipeline(definition: str, meridian: str, inverse: bool) -> None:
    """Keep a local frame's PROJ pipeline as a template for the other meridians, where its meridian appears once."""
    if definition.count(f"lon_0={meridian} ") != 1 or "{" in definition or "}" in definition:
        return
    _TRANSFORMERS.__dict__["local_pipelines"][inverse] = definition.replace(f"lon_0={meridian} ", "lon_0={meridian} ")


def wgs84_to(crs: str):
    """The (cached) transformer from WGS-84 lon/lat to ``crs`` (``.transform(lon, lat)`` → x, y)."""
    return _transformer(crs)


_TRANSFORMERS = threading.local()  # pyproj transformers are not shared between threads


#: geometries projected per call of the transform: a national network's coordinates are never all copied at once
PROJECT_CHUNK = 8192


def project(geoms, crs: str, inverse: bool = False):
    """Shapely geometries between WGS-84 lon/lat and ``crs`` (vectorized over coordinates, ``PROJECT_CHUNK``
    geometries at a time)."""
    transformer = _transformer(crs, inverse)

    def moved(xy):
        x, y = transformer.transform(xy[:, 0], xy[:, 1])
        xy[:, 0], xy[:, 1] = x, y  # in place: shapely hands over its own copy
        return xy

    geoms = np.asarray(geoms, dtype=object)
    if geoms.ndim != 1 or len(geoms) <= PROJECT_CHUNK:
        return shapely.transform(geoms, moved)
    out = np.empty(len(geoms), dtype=object)
    for start in range(0, len(geoms), PROJECT_CHUNK):
        out[start : start + PROJECT_CHUNK] = shapely.transform(geoms[start : start + PROJECT_CHUNK], moved)
    return out


#: the largest HAL a geo-object may have (m): as ``--hal`` (an Infinity or 1e300 made every position "within HAL", and
#: an invoice with ``Infinity`` in it is not JSON)
HAL_MAX_M = 10_000.0


def hal_of(value) -> float:
    """A geo-object's ``hal_m`` property as metres, NaN unless it is a JSON number (not text, not a boolean), finite,
    positive and at most :data:`HAL_MAX_M`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return float("nan")
    try:
        hal = float(value)
    except OverflowError:  # an integer of hundreds of digits
        return float("nan")
    return hal if 0.0 < hal <= HAL_MAX_M else float("nan")


def unclosed_ring(feature) -> bool:
    """Whether a ring of the feature's GeoJSON Polygon or MultiPolygon does not end where it starts (shapely closes it
    silently; the file meant something else)."""
    geom = feature.get("geometry") if isinstance(feature, dict) else None
    if not isinstance(geom, dict):
        return False
    coords = geom.get("coordinates")
    polygons = [coords] if geom.get("type") == "Polygon" else coords if geom.get("type") == "MultiPolygon" else []
    for polygon in polygons if isinstance(polygons, list) else ():
        for ring in polygon if isinstance(polygon, list) else ():
            if isinstance(ring, list) and len(ring) >= 2 and ring[0] != ring[-1]:
                return True
    return False

