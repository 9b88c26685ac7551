"""Compile geo-object features into the store's arrays (:mod:`tollcli.geoobjects.store` writes and maps them).

Per feature only its properties are read in Python; the polygons (plain single-ring ones in bulk), their
projections to each geo-object's own metric frame and to the file's search CRS, the boxes, the WKB and the grid
(:mod:`tollcli.geoobjects.index`) are made over all of them at once, in time linear in the network.
"""

from __future__ import annotations

import numpy as np
import shapely

from tollcli.geoobjects.geojson_stream import gc_paused
from tollcli.geoobjects.index import build_grid
from tollcli.errors import DataError
from tollcli.geoobjects.city import kind_of
from tollcli.spatial import HAL_MAX_M, feature_geometries, feature_geometry, hal_of, project

#: 6: a folder of memory-mapped arrays with a grid index (5 and before: one .npz read whole); 7: the same arrays, made
#: only from files that pass the stricter check (a HAL that is a number in (0, 10 000] m, rings closed, at most 6°
#: across): a store an older version made of a file now refused is not used; 8: with a manifest of every file's
#: digest, verified before use (:mod:`tollcli.geoobjects.store_files`); 9: with each geo-object's declared environment
STORE_FORMAT = 9
#: polygons projected and written as WKB per block
CHUNK = 8192
#: the properties the store and ``geoobjects check`` read (the others — the build's report — are not kept)
USED_PROPERTIES = frozenset(("id", "name", "road_class", "hal_m", "crs_metric", "section_length_m", "length_m", "tunnel", "direction",
                             "tunnel_m", "gap_m", "axis", "opposite", "environment", "kind"))  # fmt: skip


def compile_file(path: str, columns: dict | None = None) -> tuple[dict[str, np.ndarray], str]:
    """The store's arrays of a geo-object file and the SHA-256 of the bytes they were compiled from (DataError:
    a file ``tollcli geoobjects check`` rejects, or none)."""
    with gc_paused():
        return _compile_file(path, columns)


def _compile_file(path: str, columns: dict | None) -> tuple[dict[str, np.ndarray], str]:
    from tollcli.geoobjects.geojson_stream import stream_features

    features, digest = stream_features(path, USED_PROPERTIES)  # feature by feature: never the whole text nor all
    # coordinates as lists
    return compile_features(features, path, columns=columns), digest


def compile_features(features: list, path: str, checked: bool = False, columns: dict | None = None) -> dict[str, np.ndarray]:
    """The store's arrays of geo-object features (GeoJSON dicts; ``checked``: they passed ``geoobjects check``),
    set into ``columns`` one by one as they are made (a :class:`_Spill` writes each to its file at once).

    Per feature only its properties are read in Python; polygons, projections, boxes, WKB and the grid are built
    over all of them at once."""
    if not features:
        raise DataError(f"{path}: no geo-objects")
    if not checked:
        _refuse_what_check_rejects(features, path)
    props = [(f.get("properties") if isinstance(f, dict) else None) for f in features]
    props = [p if isinstance(p, dict) else {} for p in props]
    ids = [p.get("id") for p in props]
    for i, p in enumerate(props):
        if kind_of(p) != "section":
            raise DataError(f"{path}: feature {ids[i]} is a {kind_of(p)}: gantries and zones are charged with a city tariff "
                            f"(scheme = \"city\", docs/city.md)")  # fmt: skip
    for i, fid in enumerate(ids):
        if fid in (None, ""):
            raise DataError(f"{path}: feature #{i} has no id")
    polys = feature_geometries(features, "Polygon")
    hals = np.array([hal_of(p.get("hal_m")) for p in props])
    usable = ~shapely.is_missing(polys)
    usable[usable] = np.isin(shapely.get_type_id(polys[usable]), (3, 6))  # Polygon, MultiPolygon
    usable[usable] &= ~shapely.is_empty(polys[usable]) & shapely.is_valid(polys[usable])
    usable &= hals > 0
    if not usable.all():
        i = int(np.flatnonzero(~usable)[0])
        _, why = feature_geometry(features[i])
        raise DataError(f"{path}: feature {ids[i]}: needs a valid non-empty polygon and a hal_m in (0, {HAL_MAX_M:g}] m ({why or 'run tollcli geoobjects check'})")
    ids = [str(fid) for fid in ids]
    if len(set(ids)) != len(ids):
        raise DataError(f"{path}: duplicate geo-object ids")
    from tollcli.spatial import local_frame, metric_crs

    centre_lon = shapely.get_coordinates(shapely.centroid(polys))[:, 0]
    own = [str(p["crs_metric"]) if p.get("crs_metric") else local_frame(lon) for p, lon in zip(props, centre_lon)]
    frames = tuple(sorted(set(own)))
    frame_of = {name: k for k, name in enumerate(frames)}
    frame = np.array([frame_of[f] for f in own], dtype=np.int64)
    crs = frames[0] if len(frames) == 1 else metric_crs(polys)
    n_parts, bounds, metric_wkb = np.zeros(len(polys), np.int64), np.zeros((len(polys), 4)), []
    for start in range(0, len(polys), CHUNK):  # a block of polygons projected at a time: never all of them twice
        block, block_frame = polys[start : start + CHUNK], frame[start : start + CHUNK]
        metric = np.empty(len(block), dtype=object)
        for k in np.unique(block_frame).tolist():
            metric[block_frame == k] = project(block[block_frame == k], frames[k])
        metric_wkb.append(_wkb_block(metric))
        n_parts[start : start + len(block)] = shapely.get_num_geometries(metric)
        if len(frames) == 1:
            bounds[start : start + len(block)] = shapely.bounds(metric)
    columns = {} if columns is None else columns
    _put_wkb(columns, "metric", metric_wkb)
    del metric_wkb
    if len(frames) > 1:  # the search CRS: a second pass, so that only one set of WKB blocks is held at a time
        search_wkb = []
        for start in range(0, len(polys), CHUNK):
            search = project(polys[start : start + CHUNK], crs)
            search_wkb.append(_wkb_block(search))
            bounds[start : start + len(search)] = shapely.bounds(search)
        _put_wkb(columns, "search", search_wkb)
        del search_wkb
    names_values, names_code = np.unique(np.array([str(p.get("name", "")) for p in props], dtype=object), return_inverse=True)
    class_values, class_code = np.unique(np.array([str(p.get("road_class", "")) for p in props], dtype=object), return_inverse=True)
    env_values, env_code = np.unique(np.array([str(p.get("environment") or "") for p in props], dtype=object), return_inverse=True)
    for name, value in {
        "hal_m": hals, "length_m": section_lengths(props), "tunnel_m": tunnel_lengths(props),
        "gap_m": np.nan_to_num(np.array([_float(p.get("gap_m")) for p in props])), "frame": frame, "n_parts": n_parts,
        "names_code": names_code.astype(np.int64), "road_class_code": class_code.astype(np.int64),
        "environment_code": env_code.astype(np.int64),
        "strings": {"ids": ids, "names": names_values.tolist(), "road_class": class_values.tolist(), "crs": crs,
                    "environment": env_values.tolist(),
                    "frames": list(frames), "format": STORE_FORMAT},
    }.items():  # fmt: skip
        columns[name] = value
    for name, value in build_grid(bounds).items():
        columns[name] = value
    axes = _axes(props, frames, frame)
    if axes is not None:  # an empty line stands for "no axis"
        lines = np.array([shapely.LineString() if a is None else a for a in axes], dtype=object)
        _put_wkb(columns, "axes", [_wkb_block(lines[start : start + CHUNK]) for start in range(0, len(lines), CHUNK)])
    return columns


def _refuse_what_check_rejects(features: list, path: str) -> None:
    """DataError when ``tollcli geoobjects check`` finds a problem: a network that check rejects is never charged
    (overlaps would charge one passage twice, projected coordinates would charge nothing). Runs when a file is
    compiled only: the store is made after it passes."""
    from tollcli.geoobjects.check import check_features

    problems = check_features(features)
    if problems:
        more = f" and {len(problems) - 1} more" if len(problems) > 1 else ""
        raise DataError(f"{path}: not a usable geo-object file: {problems[0]}{more} (tollcli geoobjects check {path} lists them)")


def _axes(props: list[dict], frames: tuple[str, ...], frame: np.ndarray) -> np.ndarray | None:
    """The carriageways' axes (``axis``, lon/lat) in their own frames; None where a geo-object has none."""
    have = [i for i, p in enumerate(props) if p.get("axis")]
    if not have:
        return None
    out = np.full(len(props), None, dtype=object)
    for k in sorted({int(frame[i]) for i in have}):  # one projection per frame
        mine = [i for i in have if frame[i] == k]
        out[mine] = project([shapely.LineString(np.asarray(props[i]["axis"], dtype=float)) for i in mine], frames[k])
    return out


def section_lengths(props: list[dict]) -> np.ndarray:
    """Each geo-object's section length, m: ``section_length_m`` (junction to junction), else ``length_m``, else NaN."""
    return np.array([_float(p.get("section_length_m", p.get("length_m"))) for p in props])


def tunnel_lengths(props: list[dict]) -> np.ndarray:
    """Each geo-object's length in tunnels, m: ``tunnel_m``, else its whole length when ``tunnel`` is set, else 0."""
    from tollcli.geoobjects.build import flag_set

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


def _wkb_block(geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wkb = shapely.to_wkb(geoms).tolist()
    return np.frombuffer(b"".join(wkb), np.uint8), np.array([len(w) for w in wkb], dtype=np.int64)


def _put_wkb(columns: dict, name: str, blocks: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """``<name>_wkb`` and ``<name>_ends`` from WKB blocks: streamed to their file by a store that takes blocks
    (``put_blocks``), else joined."""
    columns[f"{name}_ends"] = np.cumsum(np.concatenate([n for _, n in blocks])) if blocks else np.zeros(0, np.int64)
    if hasattr(columns, "put_blocks"):
        columns.put_blocks(f"{name}_wkb", [b for b, _ in blocks])
    else:
        columns[f"{name}_wkb"] = np.concatenate([b for b, _ in blocks]) if blocks else np.zeros(0, np.uint8)
