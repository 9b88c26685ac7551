"""Load a geo-object file for charging: parse once, then reuse a compiled copy keyed by the file's SHA-256.

A geo-object file changes rarely and is read for every log. The first load parses
the GeoJSON (plain single-ring polygons in bulk, anything else feature by feature),
checks every feature, projects each polygon to its own metric frame (its ``crs_metric``; a
feature without one gets :func:`tollcli.spatial.local_frame`) and, for the spatial index, to one
search CRS for the file, and stores the result — ids, names, road classes, HAL, frames and both
sets of metric polygons as WKB — in
``$TOLLCLI_CACHE_DIR`` (default ``~/.cache/tollcli``) under the file's SHA-256.
A file that ``tollcli geoobjects check`` rejects is refused (and never compiled).
Later loads of the same bytes read that copy (WKB keeps every coordinate bit for
bit, so invoices do not depend on the cache). ``TOLLCLI_CACHE_DIR=off`` turns the
cache off; a cache that cannot be written is silently skipped.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from tollcli.cache import cache_dir
from tollcli.errors import DataError
from tollcli.spatial import feature_geometry, project, read_features

#: the slowest traffic a tunnel's GNSS outage is allowed for (7.2 km/h, a congested tunnel), m/s
TUNNEL_MIN_SPEED_MPS = 2.0
CACHE_FORMAT = 5  # 2: compiled only after the file passed geoobjects check; 3: a metric frame per geo-object; 4: lengths, axes; 5: gaps between parts


@dataclass
class GeoObjects:
    ids: np.ndarray
    names: np.ndarray
    road_class: np.ndarray
    hal_m: np.ndarray
    polygons: np.ndarray  # each in its own metric frame, frames[frame[i]]
    crs: str  # the search CRS of the file: the spatial index and coarse queries (bounding boxes, reachability)
    tree: shapely.STRtree  # over the polygons in the search CRS
    frames: tuple[str, ...] = ()
    frame: np.ndarray | None = None  # per geo-object: index into frames
    source_sha256: str | None = None  # SHA-256 of the file's bytes these were made from (None: not from a file)
    #: per geo-object: the section's length, ground metres (``section_length_m``, else ``length_m``; NaN: none given),
    #: what per-km rates charge
    length_m: np.ndarray | None = None
    #: per geo-object: metres of it in tunnels (``tunnel_m``; the whole section when only ``tunnel`` is set; 0: none),
    #: where no GNSS reaches: passages and findings expect the gap
    tunnel_m: np.ndarray | None = None

    #: per geo-object: its axis in its own metric frame when it is a carriageway told apart from the opposite one by the
    #: direction of travel (``carriageways.py``), else None
    axes: np.ndarray | None = None
    #: per geo-object: the longest stretch of its section between two of its parts (``gap_m``; 0: one part), m — a
    #: passage spans it without a fix inside
    gap_m: np.ndarray | None = None

    def directed(self) -> np.ndarray:
        """Which geo-objects count a position only in their direction of travel."""
        if self.axes is None:
            return np.zeros(len(self.ids), bool)
        return np.array([a is not None for a in self.axes], bool)

    def tunnel_lengths_m(self) -> np.ndarray:
        return self.tunnel_m if self.tunnel_m is not None else np.zeros(len(self.ids))

    def tunnel_times_s(self) -> np.ndarray:
        """Per geo-object: how long its tunnels may keep GNSS away, s (their length at ``TUNNEL_MIN_SPEED_MPS``)."""
        return self.tunnel_lengths_m() / TUNNEL_MIN_SPEED_MPS

    def gap_times_s(self) -> np.ndarray:
        """Per geo-object: how long a passage may spend between two of its parts, s (tunnels and the longest gap
        between parts at ``TUNNEL_MIN_SPEED_MPS``: a slow vehicle crossing the stretch cut out is one passage)."""
        gaps = self.gap_m if self.gap_m is not None else np.zeros(len(self.ids))
        return (self.tunnel_lengths_m() + gaps) / TUNNEL_MIN_SPEED_MPS


def load_geoobjects(path: str) -> GeoObjects:
    """A geo-object file (as written by ``tollcli geoobjects build``) ready for recognition."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        data = None  # read_features reports it
    digest = hashlib.sha256(data).hexdigest() if data is not None else None
    cached = _cache_path(digest) if digest is not None else None
    if cached is not None and cached.exists():
        try:
            geo = _read_compiled(cached)
            geo.source_sha256 = digest
            return geo
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, shapely.errors.ShapelyError):
            pass  # a damaged copy: parse again
    _refuse_what_check_rejects(path)
    geo = _parse(path)
    geo.source_sha256 = digest  # hashed once, for the cache key and for the invoice
    if cached is not None:
        _write_compiled(cached, geo)
    return geo


def _refuse_what_check_rejects(path: str) -> None:
    """DataError when ``tollcli geoobjects check`` finds a problem: a network that check rejects is never charged
    (overlaps would charge one passage twice, projected coordinates would charge nothing). Runs on the first load
    of a file only: the compiled copy is made after it passes."""
    from tollcli.charging.geoobjects import check_geoobjects

    problems = check_geoobjects(path)
    if problems:
        more = f" and {len(problems) - 1} more" if len(problems) > 1 else ""
        raise DataError(f"{path}: not a usable geo-object file: {problems[0]}{more} (tollcli geoobjects check {path} lists them)")


def _cache_path(digest: str) -> Path | None:
    base = cache_dir()
    if base is None:
        return None
    return base / "geoobjects" / f"{digest}.v{CACHE_FORMAT}.npz"


def _parse(path: str) -> GeoObjects:
    features = read_features(path)
    if not features:
        raise DataError(f"{path}: no geo-objects")
    props = [(f.get("properties") if isinstance(f, dict) else None) for f in features]
    props = [p if isinstance(p, dict) else {} for p in props]
    ids = [p.get("id") for p in props]
    for i, fid in enumerate(ids):
        if fid in (None, ""):
            raise DataError(f"{path}: feature #{i} has no id")
    polys = _polygons(features)
    hals = np.array([_float(p.get("hal_m")) for p in props])
    usable = ~shapely.is_missing(polys)
    usable[usable] = np.isin(shapely.get_type_id(polys[usable]), (3, 6))  # Polygon, MultiPolygon
    usable[usable] &= ~shapely.is_empty(polys[usable]) & shapely.is_valid(polys[usable])
    usable &= hals > 0
    if not usable.all():
        i = int(np.flatnonzero(~usable)[0])
        _, why = feature_geometry(features[i])
        raise DataError(f"{path}: feature {ids[i]}: needs a valid non-empty polygon and hal_m > 0 ({why or 'run tollcli geoobjects check'})")
    ids = [str(fid) for fid in ids]
    if len(set(ids)) != len(ids):
        raise DataError(f"{path}: duplicate geo-object ids")
    from tollcli.spatial import local_frame, metric_crs

    centre_lon = shapely.get_coordinates(shapely.centroid(polys))[:, 0]
    own = [str(p["crs_metric"]) if p.get("crs_metric") else local_frame(lon) for p, lon in zip(props, centre_lon)]
    frames = tuple(sorted(set(own)))
    frame = np.array([frames.index(f) for f in own], dtype=np.int64)
    metric = np.empty(len(polys), dtype=object)
    for k, name in enumerate(frames):
        metric[frame == k] = project(polys[frame == k], name)
    crs = frames[0] if len(frames) == 1 else metric_crs(polys)
    search = metric if len(frames) == 1 else project(polys, crs)
    axes = _axes(props, frames, frame)
    return GeoObjects(np.array(ids, dtype=object), np.array([str(p.get("name", "")) for p in props], dtype=object),
                      np.array([str(p.get("road_class", "")) for p in props], dtype=object), hals, metric, crs,
                      shapely.STRtree(search), frames, frame, None, section_lengths(props), tunnel_lengths(props), axes,
                      np.nan_to_num(np.array([_float(p.get("gap_m")) for p in props])))  # fmt: skip


def _axes(props: list[dict], frames: tuple[str, ...], frame: np.ndarray) -> np.ndarray | None:
    """The carriageways' axes (``axis``, lon/lat) in their own frames; None where a geo-object has none."""
    have = [i for i, p in enumerate(props) if p.get("axis")]
    if not have:
        return None
    out = np.full(len(props), None, dtype=object)
    for i in have:
        out[i] = project([shapely.LineString(np.asarray(props[i]["axis"], dtype=float))], frames[frame[i]])[0]
    return out


def section_lengths(props: list[dict]) -> np.ndarray:
    """Each geo-object's section length, m: ``section_length_m`` (junction to junction), else ``length_m``, else NaN."""
    return np.array([_float(p.get("section_length_m", p.get("length_m"))) for p in props])


def tunnel_lengths(props: list[dict]) -> np.ndarray:
    """Each geo-object's length in tunnels, m: ``tunnel_m``, else its whole length when ``tunnel`` is set, else 0."""
    from tollcli.charging.geoobjects import flag_set

    out = np.zeros(len(props))
    for i, p in enumerate(props):
        given = _float(p.get("tunnel_m"))
        if np.isfinite(given) and given > 0:
            out[i] = given
        elif flag_set(p.get("tunnel")):
            whole = _float(p.get("section_length_m", p.get("length_m")))
            out[i] = whole if np.isfinite(whole) else 0.0
    return out


def _float(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _polygons(features: list) -> np.ndarray:
    """Shapely polygons of the features (None where unreadable): single-ring polygons built in bulk."""
    out = np.full(len(features), None, dtype=object)
    simple, rings = [], []
    for i, f in enumerate(features):
        geom = f.get("geometry") if isinstance(f, dict) else None
        coords = geom.get("coordinates") if isinstance(geom, dict) and geom.get("type") == "Polygon" else None
        if isinstance(coords, list) and len(coords) == 1 and isinstance(coords[0], list) and len(coords[0]) >= 4:
            try:
                ring = np.asarray(coords[0], dtype=float)
            except (TypeError, ValueError):
                ring = None
            if ring is not None and ring.ndim == 2 and ring.shape[1] == 2 and np.isfinite(ring).all():
                simple.append(i)
                rings.append(ring)
                continue
        out[i] = feature_geometry(f)[0]
    if simple:
        lengths = np.array([len(r) for r in rings])
        with np.errstate(invalid="ignore"):
            linear = shapely.linearrings(np.concatenate(rings), indices=np.repeat(np.arange(len(rings)), lengths))
        out[np.array(simple)] = shapely.polygons(linear)
    return out


def _read_compiled(path: Path) -> GeoObjects:
    with np.load(path, allow_pickle=False) as z:
        if int(z["format"]) != CACHE_FORMAT:
            raise ValueError("cache format")
        metric, search = _from_wkb(z["wkb"], z["wkb_ends"]), _from_wkb(z["wkb_search"], z["wkb_search_ends"])
        return GeoObjects(z["ids"].astype(object), z["names"].astype(object), z["road_class"].astype(object),
                          z["hal_m"], metric, str(z["crs"]), shapely.STRtree(search), tuple(z["frames"].astype(str).tolist()),
                          z["frame"], None, z["length_m"], z["tunnel_m"], _axes_from(z), z["gap_m"])  # fmt: skip


def _axes_from(z) -> np.ndarray | None:
    if "axes_wkb" not in z:
        return None
    axes = _from_wkb(z["axes_wkb"], z["axes_wkb_ends"])
    return np.array([None if a.is_empty else a for a in axes], dtype=object)


def _from_wkb(blob: np.ndarray, ends: np.ndarray) -> np.ndarray:
    data = blob.tobytes()
    starts = np.concatenate(([0], ends[:-1]))
    return shapely.from_wkb([data[a:b] for a, b in zip(starts.tolist(), ends.tolist())])


def _to_wkb(geoms) -> tuple[np.ndarray, np.ndarray]:
    wkb = shapely.to_wkb(np.asarray(geoms, dtype=object)).tolist()
    return np.frombuffer(b"".join(wkb), np.uint8), np.cumsum([len(w) for w in wkb])


def _write_compiled(path: Path, geo: GeoObjects) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        wkb, wkb_ends = _to_wkb(geo.polygons)
        wkb_search, wkb_search_ends = _to_wkb(geo.tree.geometries)
        extra = {}
        if geo.axes is not None:  # an empty line stands for "no axis"
            extra["axes_wkb"], extra["axes_wkb_ends"] = _to_wkb([shapely.LineString() if a is None else a for a in geo.axes])
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, format=CACHE_FORMAT, ids=geo.ids.astype(str), names=geo.names.astype(str),
                     road_class=geo.road_class.astype(str), hal_m=geo.hal_m, crs=geo.crs, frames=np.array(geo.frames, dtype=str),
                     frame=geo.frame, length_m=geo.length_m, tunnel_m=geo.tunnel_m, gap_m=geo.gap_m if geo.gap_m is not None else np.zeros(len(geo.ids)), wkb=wkb, wkb_ends=wkb_ends, wkb_search=wkb_search, wkb_search_ends=wkb_search_ends, **extra)  # fmt: skip
        os.replace(tmp, path)
    except OSError:
        try:
            os.unlink(tmp)  # type: ignore[possibly-undefined]
        except (OSError, NameError):
            pass
