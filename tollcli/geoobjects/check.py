"""``tollcli geoobjects check``: what makes a geo-object file unusable, each problem tied to its feature.

Run on every file before it is compiled for charging (``store.py``: a file check rejects is never
charged) and on what ``tollcli geoobjects build`` is about to write (a build never writes what check would reject):
one list of problems, in the same words everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from tollcli.spatial import HAL_MAX_M, feature_geometries, feature_geometry, hal_of, metric_crs, project, unclosed_ring
from tollcli.geoobjects.city import city_feature_problem, kind_of


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


#: pairs of geo-objects measured for overlap at a time
OVERLAP_BLOCK = 8192
#: the smallest HAL ``check`` (and ``process``) accept unless told otherwise, m
HAL_MIN_CHECK_M = 5.0
#: the widest a geo-object may be (degrees of longitude or latitude, ≈ 650 km): its metric frame is centred on it,
#: and a polygon from 2°E to 153°E was never matched (nor said so)
MAX_EXTENT_DEG = 6.0
#: the values of ``direction`` (carriageways.py reads forward/oneway/one-way as one-way; both is two-way)
DIRECTIONS = ("forward", "oneway", "one-way", "both")
#: what an operator may declare of where a geo-object's road runs (``environment``): the error model the ``model``
#: level takes there when the receiver gives no residuals (integrity/environment.py: with_declared_environment)
DECLARED_ENVIRONMENTS = ("open", "urban")
#: the length properties a charge may be priced by (per km) and their largest value (m): a section is never 1 000 km
LENGTH_PROPERTIES = ("section_length_m", "length_m", "tunnel_m", "gap_m")
MAX_LENGTH_M = 1_000_000.0


def _a_length(value) -> bool:
    """Whether a length property is a JSON number (not text, not a boolean), finite, in [0, MAX_LENGTH_M]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return 0.0 <= float(value) <= MAX_LENGTH_M
    except OverflowError:
        return False


def check_geoobjects(path: str, hal_min_m: float = HAL_MIN_CHECK_M) -> list[Finding]:
    """Problems of a geo-object file, each tied to a feature id (empty list: the file is usable)."""
    from tollcli.geoobjects.geojson_stream import gc_paused, stream_features

    with gc_paused():  # read feature by feature: a national network's file is never held whole
        return check_features(stream_features(path)[0], hal_min_m)


def check_features(features: list, hal_min_m: float = HAL_MIN_CHECK_M) -> list[Finding]:
    """Problems of geo-object features (GeoJSON dicts), each tied to a feature id (empty list: usable)."""
    findings: list[Finding] = []
    crs_seen: dict = {}
    ids: list[str] = []
    seen: set[str] = set()
    partners: dict[str, set] = {}
    polys = []
    geoms = feature_geometries(features, "Polygon")  # plain polygons in bulk; the others (and why not) one by one
    have = np.flatnonzero(~shapely.is_missing(geoms))
    valid = np.zeros(len(geoms), bool)
    valid[have] = shapely.is_valid(geoms[have])
    all_bounds = np.full((len(geoms), 4), np.nan)
    all_bounds[have] = shapely.bounds(geoms[have])
    for i, feature in enumerate(features):
        fid = _feature_id(feature, i)
        props = feature.get("properties") if isinstance(feature, dict) and isinstance(feature.get("properties"), dict) else {}
        if fid.startswith("#"):
            findings.append(Finding(fid, "missing id"))
        if fid in seen:
            findings.append(Finding(fid, "duplicate id"))
        ids.append(fid)
        seen.add(fid)
        geom, why = (geoms[i], "") if geoms[i] is not None else feature_geometry(feature)
        if kind_of(props) != "section":  # a gantry or a zone (geoobjects/city.py): its own checks
            problem = why or city_feature_problem(props, geom)
            if problem:
                findings.append(Finding(fid, problem))
            polys.append(None)
            continue
        if geom is None:
            findings.append(Finding(fid, why))
            polys.append(None)
            continue
        if geom.is_empty or geom.geom_type not in ("Polygon", "MultiPolygon"):
            findings.append(Finding(fid, f"geometry must be a non-empty Polygon, got {geom.geom_type}{' (empty)' if geom.is_empty else ''}"))
            polys.append(None)
            continue
        bounds = all_bounds[i]
        if (np.abs(bounds[[0, 2]]) > 180).any() or (np.abs(bounds[[1, 3]]) > 90).any():
            findings.append(Finding(fid, "coordinates are not WGS-84 longitude/latitude (wrong CRS?)"))
        elif max(bounds[2] - bounds[0], bounds[3] - bounds[1]) > MAX_EXTENT_DEG:
            findings.append(Finding(fid, f"spans {bounds[2] - bounds[0]:.1f}° of longitude and {bounds[3] - bounds[1]:.1f}° of latitude: "
                                         f"no metric frame holds it faithfully (a geo-object is a stretch of road or a zone, "
                                         f"at most {MAX_EXTENT_DEG:g}° across)"))  # fmt: skip
        if unclosed_ring(feature):
            findings.append(Finding(fid, "a ring is not closed (GeoJSON: its last point repeats its first)"))
            polys.append(None)
            continue
        if not valid[i]:
            findings.append(Finding(fid, f"invalid geometry: {shapely.is_valid_reason(geom)}"))
        partners[fid] = set(map(str, props.get("opposite") or ()))
        if "axis" in props and not _is_axis(props["axis"]):
            findings.append(Finding(fid, "axis must be a list of ≥ 2 [longitude, latitude] points (the direction of travel)"))
        crs_problem = _crs_problem(props.get("crs_metric"), crs_seen)
        if crs_problem:
            findings.append(Finding(fid, crs_problem))
        for name in LENGTH_PROPERTIES:
            if name in props and props[name] is not None and not _a_length(props[name]):
                findings.append(Finding(fid, f"{name} {str(props[name])[:40]!r} is not a length: give metres, a number in [0, {MAX_LENGTH_M:g}]"))
        if props.get("direction") is not None and str(props["direction"]).lower() not in DIRECTIONS:
            findings.append(Finding(fid, f"direction {str(props['direction'])[:40]!r} is none of {', '.join(DIRECTIONS)} "
                                         "(a one-way road read as two-way would charge the wrong carriageway)"))  # fmt: skip
        if props.get("environment") not in (None, "") and props["environment"] not in DECLARED_ENVIRONMENTS:
            findings.append(Finding(fid, f"environment {str(props['environment'])[:40]!r} is none of {', '.join(DECLARED_ENVIRONMENTS)} "
                                         "(the operator's declaration of where the road runs)"))  # fmt: skip
        if "road_class" in props and not isinstance(props["road_class"], str):
            findings.append(Finding(fid, f"road_class {str(props['road_class'])[:40]!r} is not a name (text)"))
        hal = props.get("hal_m")
        hal_value = hal_of(hal)
        if isinstance(hal, bool) or not isinstance(hal, (int, float)):
            findings.append(Finding(fid, f"hal_m missing or not a number ({str(hal)[:40]!r})"))
        elif not np.isfinite(hal_value):
            findings.append(Finding(fid, f"hal_m {str(hal)[:40]} is not a HAL: give metres in (0, {HAL_MAX_M:g}]"))
        elif not hal_value >= hal_min_m:
            findings.append(Finding(fid, f"hal_m {hal_value:g} m below the minimum {hal_min_m:g} m"))
        polys.append(geom if valid[i] else None)
    usable = [(fid, p) for fid, p in zip(ids, polys) if p is not None]
    if len(usable) > 1:
        findings += _overlaps([fid for fid, _ in usable], np.array([p for _, p in usable], dtype=object), partners)
    return findings


def _overlaps(ids: list[str], wgs84: np.ndarray, partners: dict[str, set]) -> list[Finding]:
    """Geo-objects overlapping by more than 1 m² (opposite carriageways may), in file order. Pairs whose boxes meet
    in longitude/latitude are measured in one metric CRS a block at a time (never all polygons projected at once)."""
    crs = metric_crs(wgs84)
    a, b = shapely.STRtree(wgs84).query(wgs84)
    a, b = a[a < b], b[a < b]
    order = np.lexsort((b, a))
    a, b = a[order], b[order]
    out = []
    for start in range(0, len(a), OVERLAP_BLOCK):
        pa, pb = a[start : start + OVERLAP_BLOCK], b[start : start + OVERLAP_BLOCK]
        members = np.unique(np.r_[pa, pb])
        metric = project(wgs84[members], crs)
        ma, mb = metric[np.searchsorted(members, pa)], metric[np.searchsorted(members, pb)]
        hit = np.flatnonzero(shapely.intersects(ma, mb))
        for k in hit.tolist():
            i, j = int(pa[k]), int(pb[k])
            if ids[j] not in partners.get(ids[i], ()):  # opposite carriageways may overlap
                area = shapely.intersection(ma[k], mb[k]).area
                if area > 1.0:
                    out.append(Finding(ids[i], f"overlaps {ids[j]} ({area:.0f} m²)"))
    return out


def _is_axis(value) -> bool:
    try:
        xy = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return xy.ndim == 2 and xy.shape[0] >= 2 and xy.shape[1] == 2 and bool(np.isfinite(xy).all()) \
        and bool((np.abs(xy[:, 0]) <= 180).all() and (np.abs(xy[:, 1]) <= 90).all())
