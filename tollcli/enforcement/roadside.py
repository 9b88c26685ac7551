"""Roadside cross-check: RFID/DSRC tag reads at gantries against the GNSS trip.

Reads (CSV: ``tag_id``, ``gantry_id``, ``time_utc``) and gantries (GeoJSON: Point or
LineString features with an ``id``) are compared with the trip's fixes:

``read_far_from_trip``  a read of the vehicle's tag while the trip was ≥ ``distance_tol_m`` from the
                        gantry (within ``time_tol_s`` of the read): a cloned tag, or a wrong trip;
``read_without_trip``   a read when the trip has no fix within ``time_tol_s``: the log is silent then
                        (possible stolen vehicle or switched-off unit, or a cloned tag);
``missed_read``         the trip passes within ``pass_dist_m`` of a gantry and no read of the tag lies
                        within ``time_tol_s`` of the passage: missing or shielded tag.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import shapely

from tollcli.enforcement.trip import fixes
from tollcli.errors import DataError
from tollcli.spatial import feature_geometry, metric_crs, project, read_features
from tollcli.times import epoch_seconds, iso_from_seconds, nearest_index


@dataclass(frozen=True)
class RoadsideSettings:
    time_tol_s: float = 30.0
    distance_tol_m: float = 1000.0
    pass_dist_m: float = 50.0


def read_reads(path: str) -> pd.DataFrame:
    from tollcli.io.sources import read_table

    table = read_table(path)
    missing = [c for c in ("tag_id", "gantry_id", "time_utc") if c not in table.columns]
    if missing:
        raise DataError(f"{path}: tag reads need columns tag_id, gantry_id, time_utc (missing {', '.join(missing)})")
    times = pd.to_datetime(table["time_utc"], utc=True, errors="coerce")
    bad = np.flatnonzero(times.isna().to_numpy())
    if bad.size:
        raise DataError(f"{path}: line {bad[0] + 2}: time_utc {table['time_utc'].iat[bad[0]]!r} is not a time")
    return table.assign(time_utc=times, tag_id=table["tag_id"].astype(str), gantry_id=table["gantry_id"].astype(str))


def read_gantries(path: str) -> tuple[list[str], np.ndarray, str]:
    """Gantry ids, their geometries in a metric CRS, and that CRS."""
    ids, geoms = [], []
    for i, feature in enumerate(read_features(path)):
        geom, why = feature_geometry(feature)
        gid = (feature.get("properties") or {}).get("id")
        if geom is None or gid in (None, ""):
            raise DataError(f"{path}: feature #{i}: a gantry needs an id and a Point or LineString ({why or 'no id'})")
        ids.append(str(gid))
        geoms.append(geom)
    if not ids:
        raise DataError(f"{path}: no gantries")
    crs = metric_crs(geoms)
    return ids, project(np.asarray(geoms, dtype=object), crs), crs


def cross_check(epochs: pd.DataFrame, reads: pd.DataFrame, gantry_ids: list[str], gantries: np.ndarray, crs: str,
                tag: str | None = None, settings: RoadsideSettings = RoadsideSettings()) -> list[dict]:  # fmt: skip
    """Findings of the module docstring, in time order."""
    from pyproj import Transformer

    t = epoch_seconds(epochs)
    fx = fixes(epochs, t)
    if tag is not None:
        reads = reads[reads["tag_id"] == str(tag)]
    index = {g: i for i, g in enumerate(gantry_ids)}
    unknown = sorted(set(reads["gantry_id"]) - set(index))
    if unknown:
        raise DataError(f"tag reads name gantries not in the gantry file: {', '.join(unknown[:5])}")
    tr = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x, y = (np.asarray(v, float) for v in tr.transform(fx.lon_deg, fx.lat_deg))
    out = []
    read_t = reads["time_utc"].dt.tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64) / 1000.0
    # each read: the nearest fix in time
    if fx.t_s.size:
        k, gap = nearest_index(fx.t_s, read_t)
        near = gap <= settings.time_tol_s
    else:
        k = np.zeros(read_t.size, int)
        near = np.zeros(read_t.size, bool)
    g_idx = reads["gantry_id"].map(index).to_numpy(int)
    for r in range(len(reads)):  # one per tag read (a handful per trip)
        gantry = gantries[g_idx[r]]
        base = {"tag_id": reads["tag_id"].iat[r], "gantry_id": reads["gantry_id"].iat[r], "read_utc": iso_from_seconds(read_t[r])}
        if not near[r]:
            out.append({"kind": "read_without_trip", **base, "nearest_fix_s": float(np.min(np.abs(fx.t_s - read_t[r]))) if fx.t_s.size else None})
            continue
        d = float(shapely.distance(shapely.Point(x[k[r]], y[k[r]]), gantry))
        if d >= settings.distance_tol_m:
            out.append({"kind": "read_far_from_trip", **base, "trip_utc": iso_from_seconds(fx.t_s[k[r]]), "trip_lat_deg": round(float(fx.lat_deg[k[r]]), 7),
                        "trip_lon_deg": round(float(fx.lon_deg[k[r]]), 7), "distance_m": round(d, 1)})  # fmt: skip
    # passages: fixes within pass_dist of a gantry, grouped into passes; each needs a read of that gantry
    pts = shapely.points(x, y)
    tree = shapely.STRtree(gantries)
    fix_i, gan_i = tree.query(pts, predicate="dwithin", distance=settings.pass_dist_m)
    for g in np.unique(gan_i):
        times = np.sort(fx.t_s[fix_i[gan_i == g]])
        splits = np.flatnonzero(np.diff(times) > 120.0)
        for block in np.split(times, splits + 1):
            mid = float(np.median(block))
            mine = read_t[g_idx == g] if len(reads) else np.zeros(0)
            if not np.any(np.abs(mine - mid) <= settings.time_tol_s + (block[-1] - block[0]) / 2):
                out.append({"kind": "missed_read", "tag_id": tag, "gantry_id": gantry_ids[g], "pass_utc": iso_from_seconds(mid),
                            "fixes_near": int(block.size)})  # fmt: skip
    out.sort(key=lambda f: f.get("read_utc") or f.get("pass_utc"))
    return out

