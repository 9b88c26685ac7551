"""GeoJSON features and metric map projections, shared by every room that handles roads or geo-objects.

Reading a FeatureCollection (WGS-84 longitude/latitude, RFC 7946), a feature's
geometry without raising, the metric CRS (UTM zone) of a set of lines, and
WGS-84 ↔ metric transforms (pyproj transformers made once per thread).
"""

from __future__ import annotations

import math
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
    try:
        with np.errstate(invalid="ignore"):
            geom = shapely.geometry.shape(feature.get("geometry") or {})
    except (ValueError, TypeError, AttributeError, KeyError, IndexError, shapely.errors.ShapelyError) as exc:
        return None, f"unreadable geometry ({type(exc).__name__}: {exc})"
    coords = shapely.get_coordinates(geom)
    if not np.isfinite(coords).all():
        return None, "coordinates must be finite numbers"
    return geom, ""


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
    """WGS-84 lon/lat → ``crs`` (or back), made once per thread (building one costs milliseconds)."""
    from pyproj import Transformer

    cache = _TRANSFORMERS.__dict__.setdefault("by_crs", {})
    key = (crs, inverse)
    if key not in cache:
        from pyproj.exceptions import CRSError

        src, dst = ("EPSG:4326", crs) if not inverse else (crs, "EPSG:4326")
        try:
            cache[key] = Transformer.from_crs(src, dst, always_xy=True)
        except CRSError:
            raise DataError(f"unknown coordinate reference system {crs!r}") from None
    return cache[key]


def wgs84_to(crs: str):
    """The (cached) transformer from WGS-84 lon/lat to ``crs`` (``.transform(lon, lat)`` → x, y)."""
    return _transformer(crs)


_TRANSFORMERS = threading.local()  # pyproj transformers are not shared between threads


def project(geoms, crs: str, inverse: bool = False):
    """Shapely geometries between WGS-84 lon/lat and ``crs`` (vectorized over coordinates)."""
    transformer = _transformer(crs, inverse)
    return shapely.transform(np.asarray(geoms, dtype=object), lambda xy: np.column_stack(transformer.transform(xy[:, 0], xy[:, 1])))
