"""Topological map matching onto a road network, vectorized over epochs.

Roads: the LineStrings of a roads GeoJSON (``id``, ``tolled``, optional ``direction``: ``forward`` for
one-way in drawing order). Per epoch, in the network's metric CRS:

1. candidates: every road within ``search_m`` (100 m) of the fix (one spatial-index query for all epochs);
2. point-to-curve with heading: distance to the road and Δθ between the road's direction at the
   projected point and the GPS course (two-way roads: the nearer of the two directions, so Δθ ∈
   [0°, 90°]; one-way: [0°, 180°]); cost = distance + ``heading_weight_m_per_deg``·Δθ (heading only
   when the vehicle moves ≥ 2 m/s, where the course is meaningful);
3. topology: the match may move from one road to another only where they are connected (touch
   within ``connect_tol_m``); otherwise the previous road is kept for as long as it is still a
   candidate. This is decided per run of equal best candidates (a loop over road changes, not epochs);
   a gap of more than ``reset_s`` without fixes starts afresh (a wrong first match is the method's
   known weakness).

Columns: ``matched_road`` ('' when none within reach), ``match_dist_m``, ``road_heading_deg``,
``delta_theta_deg``, ``matched_x_m``/``matched_y_m`` (the projected point, metric CRS) and ``along_m``
(position along the matched road).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import shapely

from tollcli.errors import DataError
from tollcli.spatial import (
    feature_geometry,
    metric_crs,
    project,
    read_features,
    wgs84_to,
)


@dataclass(frozen=True)
class Roads:
    ids: np.ndarray
    tolled: np.ndarray
    oneway: np.ndarray
    lines: np.ndarray  # metric CRS
    crs: str
    tree: shapely.STRtree
    connected: frozenset  # pairs (i, j), i < j, of roads that touch


@dataclass(frozen=True)
class MatchParams:
    search_m: float = 100.0
    heading_weight_m_per_deg: float = 0.5
    min_speed_mps: float = 2.0
    connect_tol_m: float = 1.0
    reset_s: float = 30.0


@dataclass(frozen=True)
class MatchState:
    """What the matching carries into a later stretch of the same log (see :func:`match_with_trace`)."""

    current: int = -1  # road index the topology rule holds (-1: none)
    last_t: float = -np.inf  # time of the last epoch with a candidate before the stretch (s)
    last_trusted: float = np.nan  # road index of the last trusted match (NaN: none)


@dataclass(frozen=True)
class MatchTrace:
    """Where the matching's state changes, to restart it exactly at a later row of the same table."""

    run_start: np.ndarray  # first row of each run of equal best roads
    run_end: np.ndarray  # last row of each run
    before: list  # (current, last_t) before each run, and after the last one
    trusted_fill: np.ndarray  # per row: road index of the last trusted match up to it (NaN: none)
    state_in: MatchState

    def restart(self, row: int) -> tuple[int, MatchState]:
        """The row at or before ``row`` where matching can restart, and the state before it."""
        k = int(np.searchsorted(self.run_end, row, side="left"))  # first run ending at or after row
        if k < self.run_start.size and self.run_start[k] < row:
            row = int(self.run_start[k])  # inside a run: restart at its start
        current, last_t = self.before[k]
        trusted = self.trusted_fill[row - 1] if row > 0 else self.state_in.last_trusted
        return row, MatchState(int(current), float(last_t), float(trusted))


def load_roads(path: str, connect_tol_m: float = 1.0) -> Roads:
    ids, tolled, oneway, geoms = [], [], [], []
    for i, feature in enumerate(read_features(path)):
        geom, why = feature_geometry(feature)
        if geom is None or geom.geom_type != "LineString":
            continue
        props = feature.get("properties") or {}
        ids.append(str(props.get("id", i)))
        tolled.append(props.get("tolled", True) is not False)
        oneway.append(str(props.get("direction") or "").lower() in ("forward", "oneway", "one-way"))
        geoms.append(geom)
    if not geoms:
        raise DataError(f"{path}: no LineString roads to match onto")
    crs = metric_crs(geoms)
    lines = project(np.asarray(geoms, dtype=object), crs)
    tree = shapely.STRtree(lines)
    a, b = tree.query(lines, predicate="dwithin", distance=connect_tol_m)
    pairs = frozenset((int(i), int(j)) for i, j in zip(a, b) if i < j)
    return Roads(np.array(ids, dtype=object), np.array(tolled), np.array(oneway), lines, crs, tree, pairs)


def roads_of_geoobjects(roads: Roads, geo_ids: np.ndarray) -> np.ndarray:
    """Per geo-object id: the id of its road in the network — the same id, else the id before a section suffix
    ``/k`` (``geoobjects build`` names the sections of road ``C`` ``C/1``, ``C/2``) — or '' when there is none."""
    known = roads.ids.astype(str)
    ids = np.asarray(geo_ids, dtype=object).astype(str)
    base = np.array([g.rpartition("/")[0] for g in ids.tolist()], dtype=object)  # the id before a '/k' suffix ('' none)
    return np.where(np.isin(ids, known), ids, np.where(np.isin(base, known), base, "")).astype(object)


def distance_to_road_m(roads: Roads, road_id: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Per position: its distance (m) to the road of the network whose id is ``road_id`` (NaN: no such road)."""
    index = pd.Series(np.arange(len(roads.ids)), index=pd.Index(roads.ids.astype(str)))
    index = index[~index.index.duplicated()]
    i = index.reindex(np.asarray(road_id, dtype=object).astype(str)).to_numpy(float)
    out = np.full(i.size, np.nan)
    have = np.flatnonzero(np.isfinite(i) & np.isfinite(lat_deg) & np.isfinite(lon_deg))
    if have.size:
        x, y = (np.asarray(v, float) for v in wgs84_to(roads.crs).transform(lon_deg[have], lat_deg[have]))
        out[have] = shapely.distance(shapely.points(x, y), roads.lines[i[have].astype(np.int64)])
    return out


def _heading_at(lines: np.ndarray, along: np.ndarray) -> np.ndarray:
    """Direction of each line at distance ``along`` (degrees clockwise from grid north)."""
    length = shapely.length(lines)
    a = shapely.line_interpolate_point(lines, np.clip(along - 1.0, 0.0, length))
    b = shapely.line_interpolate_point(lines, np.clip(along + 1.0, 0.0, length))
    return np.degrees(np.arctan2(shapely.get_x(b) - shapely.get_x(a), shapely.get_y(b) - shapely.get_y(a))) % 360.0


def delta_heading_deg(course_deg, road_deg, oneway) -> np.ndarray:
    """|course − road direction| in [0°, 180°]; for two-way roads the nearer direction, [0°, 90°]."""
    d = np.abs((np.asarray(course_deg) - np.asarray(road_deg) + 180.0) % 360.0 - 180.0)
    return np.where(oneway, d, np.minimum(d, 180.0 - d))


def match(epochs: pd.DataFrame, roads: Roads, params: MatchParams = MatchParams(), trusted: np.ndarray | None = None) -> pd.DataFrame:
    """The matched road and the matching geometry per epoch (columns of the module docstring).

    ``trusted`` (per epoch, e.g. RAIM-valid): only trusted fixes may move the match to another road;
    an untrusted fix keeps the current road when it is within reach (else it is unmatched), so a
    detected fault cannot drag the match onto a road the vehicle is not on.
    """
    return match_with_trace(epochs, roads, params, trusted)[0]


def match_with_trace(epochs: pd.DataFrame, roads: Roads, params: MatchParams = MatchParams(), trusted: np.ndarray | None = None,
                     state: MatchState = MatchState()) -> tuple[pd.DataFrame, MatchTrace]:  # fmt: skip
    """:func:`match` for a stretch of a log that starts in ``state``, and the trace to restart it later.

    Matching rows ``r…`` of a table in :meth:`MatchTrace.restart`'s state gives what matching the
    whole table gives for those rows.
    """
    from tollcli.times import epoch_seconds

    n = len(epochs)
    lon, lat = epochs["lon_deg"].to_numpy(float), epochs["lat_deg"].to_numpy(float)
    x, y = (np.asarray(v, float) for v in wgs84_to(roads.crs).transform(lon, lat))
    course = epochs["course_deg"].to_numpy(float) if "course_deg" in epochs else np.full(n, np.nan)
    speed = epochs["speed_mps"].to_numpy(float) if "speed_mps" in epochs else np.full(n, np.nan)
    have = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    pts = shapely.points(x[have], y[have])
    pi, ri = roads.tree.query(pts, predicate="dwithin", distance=params.search_m)
    e = have[pi]
    line = roads.lines[ri]
    dist = shapely.distance(pts[pi], line)
    along = shapely.line_locate_point(line, pts[pi])
    road_dir = _heading_at(line, along)
    dth = delta_heading_deg(course[e], road_dir, roads.oneway[ri])
    use_heading = np.isfinite(dth) & (speed[e] >= params.min_speed_mps)
    cost = dist + np.where(use_heading, params.heading_weight_m_per_deg * dth, 0.0)
    # best candidate per epoch
    order = np.lexsort((cost, e))
    first = np.concatenate([[True], e[order][1:] != e[order][:-1]]) if order.size else np.zeros(0, bool)
    best = np.full(n, -1)
    best_pair = np.full(n, -1)
    best[e[order][first]] = ri[order][first]
    best_pair[e[order][first]] = order[first]
    decide = best if trusted is None else np.where(np.asarray(trusted, bool), best, -1)
    chosen, runs = _topology(decide, e, ri, epoch_seconds(epochs), roads, params, state)
    fill = np.full(n, np.nan)
    if trusted is not None:
        chosen, fill = _carry_current(chosen, np.asarray(trusted, bool), e, ri, state.last_trusted)
    # the chosen pair's geometry (a lookup per (epoch, road))
    key = e.astype(np.int64) * (len(roads.ids) + 1) + ri
    lookup = pd.Series(np.arange(e.size), index=key)
    want = np.flatnonzero(chosen >= 0)
    pair = np.full(n, -1)
    if want.size:
        pair[want] = lookup.reindex(want.astype(np.int64) * (len(roads.ids) + 1) + chosen[want]).to_numpy()
    ok = pair >= 0
    out = pd.DataFrame({
        "matched_road": pd.array(np.where(ok, roads.ids[np.maximum(chosen, 0)], ""), dtype="string"),
        "match_dist_m": np.where(ok, dist[np.maximum(pair, 0)] if e.size else np.nan, np.nan),
        "road_heading_deg": np.where(ok, road_dir[np.maximum(pair, 0)] if e.size else np.nan, np.nan),
        "delta_theta_deg": np.where(ok, dth[np.maximum(pair, 0)] if e.size else np.nan, np.nan),
        "along_m": np.where(ok, along[np.maximum(pair, 0)] if e.size else np.nan, np.nan),
    })  # fmt: skip
    proj = shapely.line_interpolate_point(roads.lines[np.maximum(chosen, 0)], np.nan_to_num(out["along_m"].to_numpy()))
    out["matched_x_m"] = np.where(ok, shapely.get_x(proj), np.nan)
    out["matched_y_m"] = np.where(ok, shapely.get_y(proj), np.nan)
    return out, MatchTrace(*runs, trusted_fill=fill, state_in=state)


def _carry_current(chosen: np.ndarray, trusted: np.ndarray, e: np.ndarray, ri: np.ndarray,
                   last_trusted: float = np.nan) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Untrusted epochs take the last trusted match when that road is among their candidates.

    Also returns, per epoch, that last trusted match (NaN: none yet; ``last_trusted`` before the first).
    """
    filled = pd.Series(np.where(trusted & (chosen >= 0), chosen, np.nan)).ffill().to_numpy()
    filled = np.where(np.isnan(filled), last_trusted, filled)  # only the leading epochs are still NaN
    rows = np.flatnonzero(~trusted & np.isfinite(filled))
    out = chosen.copy()
    out[~trusted] = -1
    if rows.size and e.size:
        road = filled[rows].astype(np.int64)
        ok = pd.MultiIndex.from_arrays([rows, road]).isin(pd.MultiIndex.from_arrays([e, ri]))
        out[rows[ok]] = road[ok]
    return out, filled


def _topology(best: np.ndarray, e: np.ndarray, ri: np.ndarray, t_s: np.ndarray, roads: Roads, params: MatchParams,
              state: MatchState = MatchState()) -> tuple[np.ndarray, tuple]:  # fmt: skip
    """Apply the connectivity rule to the per-epoch best roads (a loop over road changes).

    Also returns the runs (first rows, last rows) and the state (current road, last time) before each
    run and after the last.
    """
    chosen = best.copy()
    candidates = pd.Series(True, index=pd.MultiIndex.from_arrays([e, ri])) if e.size else None
    idx = np.flatnonzero(best >= 0)
    if idx.size == 0:
        return chosen, (np.zeros(0, np.int64), np.zeros(0, np.int64), [(state.current, state.last_t)])
    # runs of constant best road among epochs with a candidate, split where fixes pause > reset_s
    brk = np.concatenate([[True], (best[idx][1:] != best[idx][:-1]) | (np.diff(t_s[idx]) > params.reset_s)])
    starts = np.flatnonzero(brk)
    ends = np.concatenate([starts[1:], [idx.size]])
    current = state.current
    last_t = state.last_t
    before = []
    for s0, s1 in zip(starts, ends):
        before.append((current, last_t))
        rows = idx[s0:s1]
        road = best[rows[0]]
        if t_s[rows[0]] - last_t > params.reset_s:
            current = -1  # a fresh start after a pause
        if current < 0 or road == current or tuple(sorted((current, road))) in roads.connected:
            current = road
        else:
            # keep the previous road while it is still within reach, then move on
            still = pd.MultiIndex.from_arrays([rows, np.full(rows.size, current)]).isin(candidates.index)
            keep = np.cumprod(still).astype(bool)
            chosen[rows[keep]] = current
            if not keep.all():
                current = road
        last_t = t_s[rows[-1]]
    before.append((current, last_t))
    return chosen, (idx[starts], idx[ends - 1], before)
