"""Geo-objects: constant-HAL buffers around tolled road sections (paper 001 §II; thesis §3.4), built for a design HAL.

A road network is a GeoJSON FeatureCollection (or a GeoPackage, Shapefile, FlatGeobuf: ``geoobjects/road_files.py``)
of LineStrings (centre lines) with properties ``id``, ``name``, ``road_class``, optional ``hal_m``, optional
``direction`` and ``tolled`` (default true); or an OpenStreetMap map (``osm_network.py``). Non-tolled roads only
bound HAL and cut geo-objects. A tolled road is first cut into sections at its junctions (``road_sections.py``;
OpenStreetMap: at shared nodes).

:func:`build_from_roads` works, for every tolled section, in a metric frame chosen for it (a transverse Mercator on
the nearest whole-degree meridian, :func:`tollcli.spatial.local_frame`: ground distances to ≤ 0.05 % at any extent)
with its design HAL ``[low, high]`` (``design_hal.py``; default the papers' 25–50 m):

1. The roads it *meets* (a junction: a shared node, or for a vector file touching within ``connect_tol_m`` on its
   level) are trimmed: the parts of the centre line within ``trim_factor · HAL`` of them are cut, so the buffer does
   not reach into the roads leaving the junction (at a right angle: the end; at a shallow merge or a ramp running
   alongside, as long as the two stay that close).
2. Every other road (a ramp of another junction, a service road, a parallel street, a road crossing on another
   level), except the opposite carriageway of the same road (``carriageways.py``), is kept clear of: one closer
   than ``2 · low`` is cut around — the stretches of the centre line within ``2 · HAL`` of it are removed — and the
   nearest one beyond bounds HAL = min(high, ½ · its distance). No position within HAL of another road can then
   lie in the geo-object: a vehicle there, valid with HPL ≤ HAL, is never charged for this section.
3. A stretch shorter than a passage needs to be seen (``min_core.py``: N_th positions T_c apart at the section's
   speed) is no stretch. Where nothing of the section is left at ``low``, the section is skipped (listed, with the
   roads that took it); only where the operator asks (``hal_min_m``, ``--hal-min``) does the build fall back to the
   largest HAL down to it that leaves a stretch (listed in the build's report).
4. The geo-object is what is left buffered by HAL (round caps). A section cut around a road may keep several
   stretches: its geo-object is then a MultiPolygon of ``parts`` (``[from_m, to_m]`` along the section, in the
   polygons' order), charged once per passage through any of them (``gap_m``: the longest stretch between two
   parts, which a passage spans) at the section's length (``section_length_m``, junction to junction).

Every feature records its design (``design_hal_m``), what holds its HAL (``hal_bound``: the design, a road kept clear
of — ``nearest_road``, ``nearest_road_m`` away — or a fallback below the design) and the roads cut around (``crossings``, ``cut_m``). The output is GeoJSON in WGS-84 (RFC 7946) with the metric
frame used recorded per feature (``crs_metric``), so recognition can project positions the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from tollcli.geoobjects.carriageways import opposite_pairs
from tollcli.geoobjects.declared_environment import DeclaredEnvironments
from tollcli.geoobjects.design_hal import DesignHal
from tollcli.geoobjects.min_core import min_core_m
from tollcli.geoobjects.check import check_geoobjects  # noqa: F401  (re-exported)
from tollcli.geoobjects.section_cut import (
    cut_section,
    hal_bound,
    section_parts,
    skip_reason,
)
from tollcli.errors import DataError
from tollcli.spatial import (
    feature_geometries,
    feature_geometry,
    geojson_coordinates,
    local_frame,
    project,
)

CONNECT_TOL_M = 1.0
TRIM_FACTOR = 2.0


@dataclass(frozen=True)
class SeenBy:
    """What the recognition needs to see a passage (``N_th`` positions ``T_c`` apart), or a core length the operator
    sets (``min_core_m``): the shortest stretch a geo-object is built on."""

    n_th: int = 1
    tc_s: float = 5.0
    core_m: float | None = None

    def min_core_m(self, props: dict) -> float:
        return self.core_m if self.core_m is not None else min_core_m(props, self.n_th, self.tc_s)

    def describe(self) -> str:
        if self.core_m is not None:
            return f"{self.core_m:g} m"
        return f"the section's speed × ((N_th − 1) · T_c + 1 s), N_th {self.n_th}, T_c {self.tc_s:g} s"


def _feature_id(feature, index: int) -> str:
    props = feature.get("properties") if isinstance(feature, dict) else None
    fid = props.get("id") if isinstance(props, dict) else None
    return str(fid) if fid not in (None, "") else f"#{index}"


def _roads(features: list[dict], path: str):
    """(ids, properties, WGS-84 lines) of the road features; DataError on unusable ones (the first, in file order)."""
    ids = [_feature_id(feature, i) for i, feature in enumerate(features)]
    geoms = feature_geometries(features, "LineString")
    single = np.flatnonzero(~shapely.is_missing(geoms))
    single = single[(shapely.get_type_id(geoms[single]) == 5) & (shapely.get_num_geometries(geoms[single]) == 1)]
    geoms[single] = shapely.get_geometry(geoms[single], 0)  # a MultiLineString of one line is that line
    bad = shapely.is_missing(geoms)
    have = np.flatnonzero(~bad)
    bounds = shapely.bounds(geoms[have])
    bad[have] = (shapely.get_type_id(geoms[have]) != 1) | shapely.is_empty(geoms[have]) | (shapely.length(geoms[have]) == 0) \
        | (np.abs(bounds[:, [0, 2]]) > 180).any(axis=1) | (np.abs(bounds[:, [1, 3]]) > 90).any(axis=1)
    if bad.any():
        _road_problem(features, int(np.flatnonzero(bad)[0]), ids, path)
    props = [dict(f.get("properties") or {}) if isinstance(f.get("properties"), dict) else {} for f in features]
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise DataError(f"{path}: duplicate road ids {', '.join(dup)}")
    if not features:
        raise DataError(f"{path}: no roads")
    return ids, props, list(geoms)


def _road_problem(features: list[dict], i: int, ids: list[str], path: str) -> None:
    """Raise the DataError saying why road feature ``i`` cannot be used."""
    fid = ids[i]
    geom, why = feature_geometry(features[i])
    if geom is None:
        raise DataError(f"{path}: feature {fid}: {why}")
    if geom.geom_type == "MultiLineString" and len(geom.geoms) == 1:
        geom = geom.geoms[0]
    if geom.geom_type != "LineString" or geom.is_empty:
        raise DataError(f"{path}: feature {fid}: a road must be a LineString, got {geom.geom_type}")
    if geom.length == 0:
        raise DataError(f"{path}: feature {fid}: a road of zero length (all its points are the same)")
    raise DataError(f"{path}: feature {fid}: coordinates are not longitude/latitude degrees")


def road_level(props: dict) -> int:
    """A road's vertical level: its ``layer``, else +1 on a bridge, −1 in a tunnel, else 0 (OpenStreetMap rules)."""
    layer = props.get("layer")
    try:
        return int(layer)
    except (TypeError, ValueError):
        pass
    if flag_set(props.get("bridge")):
        return 1
    return -1 if flag_set(props.get("tunnel")) else 0


def flag_set(value) -> bool:
    """A road tag that is set (``bridge``, ``tunnel``): anything but absent, false, 0, "", "no" or "false"."""
    return value not in (None, False, "", 0) and str(value).lower() not in ("no", "0", "false")


@dataclass
class Roads:
    """Centre lines (WGS-84) with their ids and properties; ``junctions``: pairs (i, j) of roads that meet (share a
    node) when the source knows its topology (OpenStreetMap), else None: roads touching in 2-D on one level meet."""

    ids: list[str]
    props: list[dict]
    lines: list
    junctions: set[tuple[int, int]] | None = None


def is_tolled(props: dict) -> bool:
    """A road is tolled unless its ``tolled`` says otherwise (false, 0, "no", "false": as a Shapefile or GeoPackage
    stores a boolean)."""
    value = props.get("tolled", True)
    return value is None or not (value is False or str(value).strip().lower() in ("0", "0.0", "no", "false", "n", "f"))


def roads_of(path: str, connect_tol_m: float = CONNECT_TOL_M) -> Roads:
    """The roads of a vector file (GeoJSON, GeoPackage, Shapefile, FlatGeobuf), tolled ones cut at their junctions."""
    from tollcli.geoobjects.road_sections import cut_at_junctions
    from tollcli.geoobjects.road_files import read_road_features

    ids, props, lines = _roads(read_road_features(path), path)
    roads = Roads(ids, props, lines)
    tolled = np.array([is_tolled(p) for p in props])
    return cut_at_junctions(roads, connect_tol_m, np.array([road_level(p) for p in props]), tolled)


def build_geoobjects(path: str, design: DesignHal | None = None, connect_tol_m: float = CONNECT_TOL_M,
                     trim_factor: float = TRIM_FACTOR, hal_min_m: float | None = None, seen: SeenBy | None = None,
                     environments: DeclaredEnvironments | None = None) -> dict:  # fmt: skip
    """A roads file → a GeoJSON FeatureCollection of geo-objects (dict, WGS-84); DataError when none can be built."""
    doc, skipped = build_from_roads(roads_of(path, connect_tol_m), path, design, connect_tol_m, trim_factor, hal_min_m, seen=seen,
                                    environments=environments)  # fmt: skip
    if not doc["features"]:
        raise DataError(f"{path}: no tolled section could be built ({len(skipped)} skipped: {skipped[0]['reason'] if skipped else ''})")
    return doc


def build_from_roads(roads: Roads, path: str, design: DesignHal | None = None, connect_tol_m: float = CONNECT_TOL_M,
                     trim_factor: float = TRIM_FACTOR, hal_min_m: float | None = None,
                     shapely_geometry: bool = False, seen: SeenBy | None = None,
                     environments: DeclaredEnvironments | None = None) -> tuple[dict, list[dict]]:  # fmt: skip
    """Geo-objects of the tolled roads, each built in its own metric frame (:func:`tollcli.spatial.local_frame`).

    Returns the FeatureCollection (with a foreign member ``tollcli``: the design, ``hal_min_m`` and the sections
    skipped, which ``tollcli geoobjects info`` counts in the tolled length) and the sections skipped — ``{"id", "reason"}``: nothing of them can have a HAL of
    ``hal_min_m`` — in id order. Sections built below their design HAL say so in their properties
    (``hal_m`` < ``design_hal_m[0]``; :func:`fallbacks` lists them). ``shapely_geometry``: each feature's
    ``hal_min_m``: the smallest HAL to fall back to where no stretch can have the design's (None: no fallback, the
    section is skipped — a fallback only where the operator asks). ``seen``: what the recognition needs to see a
    passage, which sets the shortest core kept (:mod:`tollcli.geoobjects.min_core`). ``environments``: the environment
    the operator declares each road runs in (:mod:`tollcli.geoobjects.declared_environment`), recorded per geo-object.
    ``geometry`` is its shapely polygon (WGS-84) rather than a GeoJSON dict — what
    :func:`tollcli.spatial.feature_collection_text` writes out a few at a time (a national network's coordinates are
    never all held as Python lists).
    """
    design = design or DesignHal()
    seen = seen or SeenBy()
    environments = environments or DeclaredEnvironments()
    props, lines = roads.props, roads.lines
    tolled = np.array([is_tolled(p) for p in props])
    if not tolled.any():
        raise DataError(f"{path}: no tolled road (every feature has tolled: false)")
    lines = np.asarray(lines, dtype=object)
    centre_lon = shapely.get_coordinates(shapely.centroid(lines))[:, 0]
    frames = np.array([local_frame(lon) for lon in centre_lon], dtype=object)
    levels = np.array([road_level(p) for p in props])
    features: dict[int, dict] = {}
    skipped: list[dict] = []
    for frame in sorted(set(frames[tolled])):
        group = np.flatnonzero(tolled & (frames == frame))
        built, gone = _build_in_frame(group, frame, roads, lines, levels, design, connect_tol_m, trim_factor, hal_min_m,
                                      shapely_geometry, seen, environments)  # fmt: skip
        features.update(built)
        skipped += gone
    order = sorted(features, key=lambda i: roads.ids[i])  # by id: the same file whatever order the roads came in
    skipped = sorted(skipped, key=lambda s: s["id"])
    build = {"design_hal_m": design.describe(), "hal_min_m": hal_min_m, "skipped": skipped}  # for geoobjects info
    if seen != SeenBy():
        build["min_core"] = seen.describe()
    if environments != DeclaredEnvironments():
        build["environment"] = environments.describe()
    return {"type": "FeatureCollection", "features": [features[i] for i in order], "tollcli": build}, skipped


def fallbacks(doc: dict) -> list[dict]:
    """The geo-objects built below their design HAL: ``{"id", "hal_m", "design_hal_m"}``."""
    out = []
    for f in doc["features"]:
        p = f["properties"]
        if p["hal_m"] < p["design_hal_m"][0]:
            out.append({"id": p["id"], "hal_m": p["hal_m"], "design_hal_m": p["design_hal_m"]})
    return out


#: buffered geo-objects are densified to this vertex spacing (m) before going back to longitude/latitude, so that
#: a straight edge in the metric frame stays within a millimetre of the edge between its vertices in any frame
SEGMENT_M = 100.0
def _build_in_frame(group, frame, roads, lines, levels, design, connect_tol_m, trim_factor, hal_min_m, shapely_geometry=False,
                    seen: SeenBy | None = None, environments: DeclaredEnvironments | None = None):  # fmt: skip
    seen = seen or SeenBy()
    environments = environments or DeclaredEnvironments()
    ids, props = roads.ids, roads.props
    metric = project(lines, frame)
    tree = shapely.STRtree(metric)
    ranges = [design.for_road(props[i]) for i in group]
    reach = 2 * max(high for _, high in ranges)
    left, right = tree.query(metric[group], predicate="dwithin", distance=reach)
    left = group[left]
    by_section = np.argsort(left, kind="stable")  # grouped by section (the order within each kept)
    left, right = left[by_section], right[by_section]
    other = left != right
    left, right = left[other], right[other]
    dist = shapely.distance(metric[left], metric[right])
    if roads.junctions is None:
        meets = (dist <= connect_tol_m) & (levels[left] == levels[right])
    else:
        meets = np.array([(a, b) in roads.junctions or (b, a) in roads.junctions for a, b in zip(left.tolist(), right.tolist())], bool)
    opposite = opposite_pairs(left, right, metric, props, meets)  # carriageways of one road: told apart by direction
    kept_clear = ~meets & ~opposite
    first = np.searchsorted(left, group, side="left")  # the pairs come grouped by section, sections in order
    last = np.searchsorted(left, group, side="right")
    built, skipped, polygons = {}, [], []
    for i, (low, high), a, b in zip(group.tolist(), ranges, first.tolist(), last.tolist()):
        line = metric[i]
        mine = slice(a, b)  # this section's pairs (a boolean mask over all pairs would make the loop quadratic)
        met = right[mine][meets[mine]]
        met_union = shapely.union_all(metric[met]) if met.size else None
        others, other_dist = right[mine][kept_clear[mine]], dist[mine][kept_clear[mine]]
        shortest = seen.min_core_m(props[i])
        cut = cut_section(line, met_union, others, other_dist, metric, low, high, trim_factor, hal_min_m, shortest)
        if cut is None:
            floor = hal_min_m if hal_min_m is not None and hal_min_m < low else low
            skipped.append({"id": ids[i], "section_length_m": round(line.length, 1), "min_core_m": shortest,
                            "reason": skip_reason(line, met_union, others, other_dist, metric, ids, trim_factor, floor, shortest,
                                                  met)})  # fmt: skip
            continue
        polys, spans = section_parts(line, cut.core, cut.hal, frame)
        polygons.append(polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys))
        properties = {
            "id": ids[i], "name": props[i].get("name", ""), "road_class": props[i].get("road_class", ""),
            "direction": props[i].get("direction"), "hal_m": round(cut.hal, 3), "crs_metric": frame,
            "length_m": round(cut.core.length, 1), "section_length_m": round(line.length, 1),
            "design_hal_m": [low, high],
        }  # fmt: skip
        properties.update(hal_bound(cut, metric[others], [ids[j] for j in others], low))
        declared = environments.for_road(props[i])
        if declared:
            properties["environment"] = declared
        if cut.near.size:
            properties.update(crossings=sorted(ids[j] for j in cut.near), cut_m=round(cut.cut_m, 1))
        if spans is not None:
            gaps = [b[0] - a[1] for a, b in zip(spans[:-1], spans[1:])]
            properties.update(parts=spans, gap_m=round(max(0.0, *gaps), 1))
        partners = right[mine][opposite[mine]]
        if partners.size:  # a carriageway: its positions count only in its direction of travel, along this axis
            axis = shapely.get_coordinates(project([line], frame, inverse=True)[0])
            properties.update(opposite=sorted(ids[j] for j in partners), axis=np.round(axis, 7).tolist())
        for key in PASSED_THROUGH:
            if props[i].get(key) not in (None, ""):
                properties[key] = props[i][key]
        built[int(i)] = {"type": "Feature", "properties": properties}
    # back to longitude/latitude in bulk: one projection and one pass over the coordinates for the whole frame
    wgs84 = project(shapely.segmentize(np.asarray(polygons, dtype=object), SEGMENT_M), frame, inverse=True) if polygons else []
    if shapely_geometry:
        for feature, polygon in zip(built.values(), wgs84):
            feature["geometry"] = polygon
        return built, skipped
    for feature, polygon, coordinates in zip(built.values(), wgs84, geojson_coordinates(wgs84)):
        feature["geometry"] = {"type": polygon.geom_type, "coordinates": coordinates}
    return built, skipped


#: road properties a geo-object keeps (OpenStreetMap ways, reference, travel direction, tunnel flag)
PASSED_THROUGH = ("osm_way_ids", "ref", "oneway", "tunnel", "tunnel_m", "maxspeed")
