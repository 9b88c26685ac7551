"""How much of a tolled section a design HAL keeps: trims at its junctions, cuts around the roads it keeps clear of,
and the fallback to the largest HAL that leaves a stretch (the rules: :mod:`tollcli.geoobjects.build`).

Every function works on one section in its metric frame: ``line`` (its centre line), ``met_union`` (the roads it
meets, merged; None), ``others`` / ``other_dist`` (indices and distances of the other roads within reach, which it
keeps clear of) and ``metric`` (every road's line in that frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

#: the shortest stretch of centre line a geo-object is built on, m
MIN_CORE_M = 1.0
#: the fallback HAL is found to this resolution, m
HAL_STEP_M = 0.01
#: a buffer of quad_segs=16 is a polygon inscribed in the circle (its edges up to 1 − cos(π/64) = 0.12 % inside) and
#: GEOS simplifies its offset curves (up to 1 % of the distance): the trims and cuts are buffered 1.2 % wider, and the
#: HAL of what is left is then capped at half its exact distance to the roads cut around
CIRCUMSCRIBE = 1.01 / np.cos(np.pi / 64)


def _clear_of(geom, radius_m: float):
    """The area within ``radius_m`` of ``geom`` (a polygon that contains the whole disc around every point)."""
    return shapely.buffer(geom, radius_m * CIRCUMSCRIBE, quad_segs=16)


@dataclass
class SectionCut:
    """One way of building a section: its HAL, the centre line left, the roads cut around and how much they took."""

    hal: float
    low: float  # the design's low end it was built for (roads closer than 2·low are cut around)
    core: object
    near: np.ndarray
    cut_m: float
    trimmed_away: bool  # nothing left after the junction trims alone
    bound: int | None = None  # index into the roads kept clear of of the one that holds HAL below `high` (None: none)
    bound_m: float = float("nan")  # its distance from the section (the centre line; a road cut around: what is left)
    min_core: float = MIN_CORE_M  # the shortest core worth building on (min_core.py)

    @property
    def ok(self) -> bool:
        return not self.core.is_empty and self.core.length >= self.min_core


def _mm(value: float) -> float:
    """Whole millimetres, rounded down (a HAL never above half a distance)."""
    return float(np.floor(value * 1000.0 + 1e-6) / 1000.0)


def _attempt(line, met_union, others, other_dist, metric, low, high, trim_factor, min_core: float = MIN_CORE_M) -> SectionCut:
    """The section built for [low, high]: trim at the roads met, cut around the others closer than 2·low."""
    near = other_dist < 2 * low
    far = np.flatnonzero(~near)
    bound, bound_m, hal = None, float("nan"), float(high)
    if far.size and other_dist[far].min() / 2.0 < high:
        k = int(far[np.argmin(other_dist[far])])
        bound, bound_m, hal = k, float(other_dist[k]), float(other_dist[k]) / 2.0
    hal = _mm(hal)
    core = line
    if met_union is not None:
        core = shapely.difference(core, _clear_of(met_union, trim_factor * hal))
    trimmed_away = core.is_empty or core.length < min_core
    cut_m = 0.0
    if near.any() and not trimmed_away:
        cut_around = metric[others[near]]
        kept = shapely.difference(core, _clear_of(shapely.union_all(cut_around), 2 * hal))
        cut_m = core.length - kept.length
        core = kept
        if not core.is_empty:  # exact: no point of a road cut around within 2 · HAL of what is left
            d = shapely.distance(core, cut_around)
            if _mm(d.min() / 2.0) < hal:
                k = int(np.argmin(d))
                bound, bound_m, hal = int(np.flatnonzero(near)[k]), float(d[k]), _mm(d.min() / 2.0)
    return SectionCut(hal, low, core, others[near], cut_m, trimmed_away, bound, bound_m, min_core)


def cut_section(line, met_union, others, other_dist, metric, low, high, trim_factor, hal_min_m: float | None,
                min_core: float = MIN_CORE_M) -> SectionCut | None:  # fmt: skip
    """The section at its design HAL; else at the largest HAL down to the design's low end that leaves a stretch of
    ``min_core`` m — or, where the operator asks for a fallback (``hal_min_m`` below ``low``), down to ``hal_min_m``;
    else None."""
    cut = _attempt(line, met_union, others, other_dist, metric, low, high, trim_factor, min_core)
    if cut.ok:
        return cut
    lowest = hal_min_m if hal_min_m is not None and hal_min_m < low else low
    if lowest >= high:
        return None
    floor = _attempt(line, met_union, others, other_dist, metric, lowest, lowest, trim_factor, min_core)
    if not floor.ok:
        return None
    good, bad = lowest, high  # a stretch is left at `good`, none at `bad` (fewer roads cut, narrower cuts below)
    best = floor
    while bad - good > HAL_STEP_M:
        mid = (good + bad) / 2.0
        trial = _attempt(line, met_union, others, other_dist, metric, mid, mid, trim_factor, min_core)
        good, bad, best = (mid, bad, trial) if trial.ok else (good, mid, best)
    stepped = round(float(np.floor(good / HAL_STEP_M) * HAL_STEP_M), 2)
    if stepped > lowest:
        trial = _attempt(line, met_union, others, other_dist, metric, stepped, stepped, trim_factor, min_core)
        if trial.ok:
            best = trial
    return best


def skip_reason(line, met_union, others, other_dist, metric, ids, trim_factor, floor_m: float, min_core: float = MIN_CORE_M,
                met: np.ndarray | None = None) -> str:  # fmt: skip
    """Why no geo-object is built on a section at HAL ``floor_m`` (its design's low end, or the fallback asked for),
    naming the roads that take it: a tolled road running along it (overlapping), the roads met at its junctions, the
    roads cut around."""
    at_floor = _attempt(line, met_union, others, other_dist, metric, floor_m, floor_m, trim_factor, min_core)
    if at_floor.trimmed_away:
        overlap = _overlapping(line, metric, met, ids)
        if overlap:
            return (f"overlapped by {overlap}: the same road twice in the network? Trimming {trim_factor:g} × HAL {floor_m:g} m "
                    f"at the roads it meets leaves {at_floor.core.length:.1f} m of its {line.length:.1f} m (less than {min_core:g} m)")  # fmt: skip
        names = ", ".join(sorted(ids[j] for j in met)) if met is not None and met.size else "none"
        return (f"too short: trimming {trim_factor:g} × HAL {floor_m:g} m at the roads it meets ({names}) leaves "
                f"{at_floor.core.length:.1f} m of its {line.length:.1f} m, less than the {min_core:g} m a passage needs to be seen")  # fmt: skip
    names = ", ".join(sorted(ids[j] for j in at_floor.near))
    return (f"no stretch of {min_core:g} m can have HAL {floor_m:g} m: {at_floor.core.length:.1f} m left after cutting "
            f"{at_floor.cut_m:.1f} m around the roads within {2 * floor_m:g} m ({names})")  # fmt: skip


#: a road met that runs along a section for this share of its length overlaps it (the same road drawn twice)
OVERLAP_SHARE = 0.5
#: ... and for at least this long, m (a stub of a few metres between two junctions overlaps nothing)
OVERLAP_MIN_M = 10.0


def _overlapping(line, metric, met: np.ndarray | None, ids) -> str:
    """The roads met that run along ``line`` for at least :data:`OVERLAP_SHARE` of it, with how far ('' when none)."""
    if met is None or not met.size or line.length <= 0:
        return ""
    along = shapely.length(shapely.intersection(line, shapely.buffer(metric[met], 1.0)))
    hits = [(ids[j], float(a)) for j, a in zip(met.tolist(), along) if a >= max(OVERLAP_SHARE * line.length, OVERLAP_MIN_M)]
    return ", ".join(f"{name} along {a:.0f} m" for name, a in sorted(hits))


def section_parts(line, core, hal: float, frame: str):
    """The buffered stretches as polygons ordered along the section, with ``[from_m, to_m]`` of each (metric)."""
    pieces = list(core.geoms) if hasattr(core, "geoms") else [core]
    pieces = [p for p in pieces if not p.is_empty]
    polygon = shapely.buffer(shapely.MultiLineString([list(p.coords) for p in pieces]) if len(pieces) > 1 else pieces[0],
                             hal, quad_segs=16)  # fmt: skip
    polys = list(polygon.geoms) if polygon.geom_type == "MultiPolygon" else [polygon]
    if len(polys) == 1:
        return polys, None
    spans = []
    for poly in polys:
        inside = [p for p in pieces if poly.intersects(p)]
        ends = [line.line_locate_point(shapely.Point(c)) for p in inside for c in (p.coords[0], p.coords[-1])]
        spans.append((min(ends), max(ends)))
    order = np.argsort([a for a, _ in spans], kind="stable")
    return [polys[k] for k in order], [[round(spans[k][0], 1), round(spans[k][1], 1)] for k in order]


def hal_bound(cut: SectionCut, others, other_ids: list[str], low: float) -> dict:
    """What holds a section's HAL (``hal_bound``): ``design`` (its design's high end), ``road`` (a road kept clear of,
    ``nearest_road``, at ``nearest_road_m`` = 2 · HAL from the section) or ``fallback`` (below the design's low end:
    the junction trims and the roads cut around left nothing at a larger HAL; ``nearest_road``: the nearest road
    kept clear of, from what is left)."""
    if cut.hal < low:
        out: dict = {"hal_bound": "fallback"}
        if len(others):
            d = shapely.distance(cut.core, others)
            k = int(np.argmin(d))
            out.update(nearest_road=other_ids[k], nearest_road_m=round(float(d[k]), 2))
        return out
    if cut.bound is None:
        return {"hal_bound": "design"}
    return {"hal_bound": "road", "nearest_road": other_ids[cut.bound], "nearest_road_m": round(cut.bound_m, 2)}
