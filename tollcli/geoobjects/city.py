"""City geo-objects: virtual gantries (a line across a road, charged when crossed) and charging zones (a polygon,
charged for presence), read from the same GeoJSON as sections, told apart by the feature's ``kind`` property.

A **gantry** is a straight ``LineString`` of two points across the road(s) it guards. Walking from its first point to
its second, the *left* side is the one a vehicle crossing ``left_to_right`` comes from. Properties:

- ``kind = "gantry"``, ``id``, optional ``name``;
- ``direction``: ``both`` (default), ``left_to_right`` or ``right_to_left`` — which crossings are charged;
- ``hal_m``: the gantry's HAL, m — a position is evidence only when it is valid at this HAL (``geoobjects build`` keeps
  twice it below the distance from the line's ends to any other road that crosses its extension, so a position on a
  parallel road can never count);
- ``depth_m`` (default 200): how far from the line, along the road, a position still counts as evidence of a side.

The gantry's **evidence area** is the rectangle from HAL before the line's first point to HAL past its last, and
±``depth_m`` across it; a crossing is proven by
valid positions in that area on each side whose bounds (HPL) do not reach the line (``charging/city_evidence.py``).

A **zone** is a ``Polygon`` (``kind = "zone"``, ``id``, optional ``name``, ``hal_m``, default 50): presence is proven
by valid positions inside it whose bound stays inside (the zone shrunk by the position's HPL).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from tollcli.errors import DataError

CITY_KINDS = ("gantry", "zone")
DIRECTIONS = ("both", "left_to_right", "right_to_left")
#: how far along the road from a gantry's line a position still counts as evidence of a side, m
DEPTH_M = 200.0
#: a zone's HAL when its feature gives none, m (the papers' largest)
ZONE_HAL_M = 50.0
#: the longest gantry line, m (a line across one road, not a cordon drawn as one line)
GANTRY_MAX_M = 200.0


def kind_of(props) -> str:
    """A feature's kind: ``section`` unless its ``kind`` property says gantry or zone (or something else, refused)."""
    kind = props.get("kind", "section") if isinstance(props, dict) else "section"
    return kind if isinstance(kind, str) else repr(kind)


def city_feature_problem(props: dict, geom) -> str:
    """Why a gantry or zone feature cannot be charged ('' when it can): its geometry and properties checked."""
    kind = kind_of(props)
    hal = props.get("hal_m", ZONE_HAL_M if kind == "zone" else None)
    if isinstance(hal, bool) or not isinstance(hal, (int, float)) or not (0 < float(hal) <= 1000):
        return f"hal_m = {hal!r}: a {kind} needs a HAL in metres, > 0 and ≤ 1000"
    if geom is None or geom.is_empty:
        return f"a {kind} needs a geometry"
    if kind == "gantry":
        if geom.geom_type != "LineString" or len(geom.coords) != 2:
            return f"a gantry is a straight LineString of two points across the road, got {geom.geom_type} of {len(shapely.get_coordinates(geom))} points"
        direction = props.get("direction", "both")
        if direction not in DIRECTIONS:
            return f"direction = {direction!r}: one of {', '.join(DIRECTIONS)}"
        depth = props.get("depth_m", DEPTH_M)
        if isinstance(depth, bool) or not isinstance(depth, (int, float)) or not (0 < float(depth) <= 2000):
            return f"depth_m = {depth!r}: metres along the road, > 0 and ≤ 2000"
    elif kind == "zone":
        if geom.geom_type not in ("Polygon", "MultiPolygon") or not geom.is_valid:
            return f"a zone is a valid Polygon or MultiPolygon, got {geom.geom_type}{'' if geom.is_valid else ' (invalid)'}"
    else:
        return f"kind = {kind!r}: one of section, {', '.join(CITY_KINDS)}"
    return ""


@dataclass
class CityNetwork:
    """The gantries and zones of a geo-object file, in one metric frame (``crs``), one entry per object."""

    ids: list[str]
    names: list[str]
    kinds: np.ndarray  # "gantry" / "zone"
    hal_m: np.ndarray
    direction: list[str]  # a gantry's charged direction ('' for a zone)
    depth_m: np.ndarray  # a gantry's evidence depth (NaN for a zone)
    geoms: list  # metric: a gantry's line, a zone's polygon
    geoms_wgs84: list
    crs: str
    source: str = ""
    source_sha256: str = ""
    areas: list = field(default_factory=list)  # metric evidence areas: a gantry's rectangle, a zone's polygon

    def __post_init__(self) -> None:
        self.areas = [evidence_area(g, d, h) if k == "gantry" else g for g, k, d, h in zip(self.geoms, self.kinds, self.depth_m, self.hal_m)]

    def __len__(self) -> int:
        return len(self.ids)

    def index_of(self, gid: str) -> int:
        return self.ids.index(gid)


def evidence_area(line, depth_m: float, hal_m: float):
    """A gantry's evidence area (metric): along the line from HAL before its first point to HAL past its last, and
    ±``depth_m`` across it."""
    (x0, y0), (x1, y1) = line.coords
    length = math.hypot(x1 - x0, y1 - y0)
    ux, uy = (x1 - x0) / length, (y1 - y0) / length
    x0, y0, x1, y1 = x0 - ux * hal_m, y0 - uy * hal_m, x1 + ux * hal_m, y1 + uy * hal_m
    nx, ny = -uy * depth_m, ux * depth_m
    return shapely.Polygon([(x0 + nx, y0 + ny), (x1 + nx, y1 + ny), (x1 - nx, y1 - ny), (x0 - nx, y0 - ny)])


def line_frame(line) -> tuple[float, float, float, float, float]:
    """A gantry line's frame: its first point (x0, y0), its unit direction (ux, uy) and its length, m."""
    (x0, y0), (x1, y1) = line.coords
    length = math.hypot(x1 - x0, y1 - y0)
    return x0, y0, (x1 - x0) / length, (y1 - y0) / length, length


def side_distance_m(line, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per metric point: its signed distance from a gantry's line, m (> 0 on the left, walking from its first point
    to its second), and its position along the line from the first point, m."""
    x0, y0, ux, uy, _ = line_frame(line)
    dx, dy = x - x0, y - y0
    return ux * dy - uy * dx, ux * dx + uy * dy


def is_city_file(features: list[dict]) -> bool:
    """Whether a feature list holds any gantry or zone."""
    return any(kind_of((f or {}).get("properties")) in CITY_KINDS for f in features if isinstance(f, dict))


def load_city_network(path: str) -> CityNetwork:
    """The gantries and zones of a GeoJSON file (DataError naming the feature for anything that cannot be charged)."""
    from tollcli.io.sources import file_sha256
    from tollcli.spatial import feature_geometry, local_frame, project, read_features

    features = read_features(path)
    rows = []
    for i, feature in enumerate(features):
        props = (feature or {}).get("properties") if isinstance(feature, dict) else None
        props = props if isinstance(props, dict) else {}
        kind = kind_of(props)
        if kind == "section":
            continue
        geom, why = feature_geometry(feature)
        gid = str(props.get("id", f"#{i}"))
        problem = why or city_feature_problem(props, geom)
        if problem:
            raise DataError(f"{path}: feature {i} ({gid}): {problem}")
        rows.append((gid, props, kind, geom))
    if not rows:
        raise DataError(f"{path}: no gantry or zone (a feature's kind property says gantry or zone)")
    ids = [r[0] for r in rows]
    if len(set(ids)) != len(ids):
        dup = sorted({g for g in ids if ids.count(g) > 1})[0]
        raise DataError(f"{path}: geo-object id {dup!r} is used twice")
    wgs = [r[3] for r in rows]
    centre = shapely.get_coordinates(np.asarray(wgs, dtype=object)).mean(axis=0)
    crs = local_frame(float(centre[0]))
    metric = list(project(np.asarray(wgs, dtype=object), crs))
    kinds = np.array([r[2] for r in rows])
    for gid, geom, kind in zip(ids, metric, kinds):
        if kind == "gantry" and not (1.0 <= geom.length <= GANTRY_MAX_M):
            raise DataError(f"{path}: gantry {gid}: its line is {geom.length:.1f} m long; a gantry spans one road (1–{GANTRY_MAX_M:g} m)")
    return CityNetwork(
        ids=ids, names=[str(r[1].get("name", r[0])) for r in rows], kinds=kinds,
        hal_m=np.array([float(r[1].get("hal_m", ZONE_HAL_M)) for r in rows]),
        direction=[str(r[1].get("direction", "both")) if r[2] == "gantry" else "" for r in rows],
        depth_m=np.array([float(r[1].get("depth_m", DEPTH_M)) if r[2] == "gantry" else math.nan for r in rows]),
        geoms=metric, geoms_wgs84=wgs, crs=crs, source=path, source_sha256=file_sha256(path),
    )  # fmt: skip
