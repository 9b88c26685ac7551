"""Which gantries a trip crossed and which zones it was in, proven by valid positions (charging/city_rules.py prices them).

**Gantry crossing.** A position is *evidence of a side* of a gantry when it is valid at the gantry's HAL, the position the
integrity check vouches for lies in the gantry's evidence area (across the line's length, within ``depth_m`` of it) and
its bound does not reach the line (|distance| > HPL). A crossing is proven by consecutive evidence positions on the two
sides at most :data:`CROSSING_GAP_S` apart; its time is interpolated between them by their distances to the line, its
direction is the order of the sides. Both evidence positions lie within HAL of the line's length, so the vehicle was within
2 × HAL of it — where ``geoobjects build`` leaves no other road.

**Crossings that are not proven** are found from the receiver's raw positions: wherever the straight path between two
consecutive positions crosses a gantry's line (or its extension by HAL), at most :data:`OUTAGE_MAX_S` apart, and no proven crossing
covers that moment, the invoice lists it as not charged with why (a gap in the positions, positions not valid, bounds
reaching the line); a path that zigzags across the line is listed once.

**Zone presence.** A position is evidence of presence when it is valid at the zone's HAL and the vouched position lies
inside the zone shrunk by its HPL. Presences are runs of evidence at most :data:`PRESENCE_GAP_S` apart; a run counts when
it holds ``n_th`` positions at least ``tc_s`` apart. Raw positions inside a zone without such a run are listed as not
charged, with their statuses.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.charging.recognition import thin_independent
from tollcli.geoobjects.city import CityNetwork, side_distance_m

#: the longest time between the evidence positions on the two sides of a gantry that still proves one crossing, s
CROSSING_GAP_S = 30.0
#: a raw path's crossing across a longer gap is not listed (the vehicle was parked, or the log is two logs: where it
#: went is not known), s
OUTAGE_MAX_S = 300.0
#: a zone presence goes on while evidence positions are at most this far apart, s
PRESENCE_GAP_S = 120.0
#: evidence positions kept per side of a crossing, and per presence
EVIDENCE_KEPT = 3
VALID_STATUSES = ("valid", "excluded_valid")

ROW_COLUMNS = ("obj", "t_s", "lat_deg", "lon_deg", "distance_m", "along_m", "hpl_m", "status", "valid", "evidence")


def object_rows(net: CityNetwork, k: int, t_s: np.ndarray, x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                lat: np.ndarray, lon: np.ndarray, hpl_m: np.ndarray, status: np.ndarray) -> pd.DataFrame:  # fmt: skip
    """One row per epoch whose raw (x, y) or vouched (vx, vy) metric position lies in object ``k``'s evidence area.

    ``distance_m``: a gantry's signed distance of the vouched position from its line (> 0 left); a zone's distance of the
    vouched position inside its boundary (< 0 outside). ``valid``: valid at the object's HAL. ``evidence``: valid, inside
    the area and the bound clear of the line (gantry) or of the boundary (zone)."""
    import shapely

    area = net.areas[k]
    near = shapely.contains_xy(area, x, y) | shapely.contains_xy(area, vx, vy)
    rows = np.flatnonzero(near)
    hpl = hpl_m[rows]
    valid = np.isin(status[rows], VALID_STATUSES) & (hpl <= net.hal_m[k])
    if net.kinds[k] == "gantry":
        d, along = side_distance_m(net.geoms[k], vx[rows], vy[rows])
        in_area = shapely.contains_xy(area, vx[rows], vy[rows])
        evidence = valid & in_area & (np.abs(d) > hpl)
    else:
        boundary = net.geoms[k].boundary
        points = shapely.points(vx[rows], vy[rows])
        inside = shapely.contains(net.geoms[k], points)
        d = np.where(inside, 1.0, -1.0) * shapely.distance(boundary, points)
        along = np.zeros(len(rows))
        evidence = valid & inside & (d > hpl)
    return pd.DataFrame({"obj": np.full(len(rows), k), "t_s": t_s[rows], "lat_deg": lat[rows], "lon_deg": lon[rows],
                         "distance_m": d, "along_m": along, "hpl_m": hpl, "status": status[rows], "valid": valid,
                         "evidence": evidence})  # fmt: skip


def path_crossings(net: CityNetwork, t_s: np.ndarray, x: np.ndarray, y: np.ndarray) -> pd.DataFrame:
    """Where the straight path between consecutive raw positions crosses a gantry's line: one row per (segment, gantry)
    with the gantry, the interpolated time, the direction and the time between the two positions (``gap_s``)."""
    out = []
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(t_s)
    t_s, x, y = t_s[ok], x[ok], y[ok]
    if len(t_s) < 2:
        return pd.DataFrame(columns=["obj", "t_s", "direction", "gap_s"])
    for k in np.flatnonzero(net.kinds == "gantry"):
        d, along = side_distance_m(net.geoms[k], x, y)
        length, hal = net.geoms[k].length, float(net.hal_m[k])
        sign = np.sign(d)
        change = np.flatnonzero((sign[:-1] * sign[1:] < 0))
        if not len(change):
            continue
        d0, d1 = d[change], d[change + 1]
        f = np.abs(d0) / (np.abs(d0) + np.abs(d1))
        a = along[change] + f * (along[change + 1] - along[change])
        hit = (a >= -hal) & (a <= length + hal)  # across the line or within HAL of its ends (its evidence area's width)
        for i, fi in zip(change[hit], f[hit]):
            out.append({"obj": int(k), "t_s": float(t_s[i] + fi * (t_s[i + 1] - t_s[i])),
                        "direction": "left_to_right" if d[i] > 0 else "right_to_left", "gap_s": float(t_s[i + 1] - t_s[i])})  # fmt: skip
    return pd.DataFrame(out, columns=["obj", "t_s", "direction", "gap_s"])


def proven_crossings(net: CityNetwork, rows: pd.DataFrame, gap_s: float = CROSSING_GAP_S, n_th: int = 1, tc_s: float = 5.0) -> list[dict]:
    """The crossings the evidence rows of every gantry prove, in time order: gantry index, time, direction, the time
    interval the crossing lies in and the evidence positions on each side (``n_th`` > 1: each side's run of evidence
    must hold ``n_th`` positions ``tc_s`` apart, as a section's passage must)."""
    out = []
    for k, group in rows[rows["evidence"]].groupby("obj", sort=True):
        if net.kinds[k] != "gantry":
            continue
        g = group.sort_values("t_s", kind="stable")
        t, d = g["t_s"].to_numpy(float), g["distance_m"].to_numpy(float)
        side = np.sign(d)
        for i in np.flatnonzero((side[:-1] != side[1:]) & (np.diff(t) <= gap_s) & (np.diff(t) > 0)):
            if n_th > 1 and min(_independent_run(t, side, i, -1, gap_s, tc_s), _independent_run(t, side, i + 1, 1, gap_s, tc_s)) < n_th:
                continue
            f = abs(d[i]) / (abs(d[i]) + abs(d[i + 1]))
            before = g.iloc[max(0, i + 1 - EVIDENCE_KEPT) : i + 1]
            after = g.iloc[i + 1 : i + 1 + EVIDENCE_KEPT]
            before = before[np.sign(before["distance_m"]) == side[i]]
            after = after[np.sign(after["distance_m"]) == side[i + 1]]
            out.append({"obj": int(k), "t_s": float(t[i] + f * (t[i + 1] - t[i])), "from_s": float(t[i]), "to_s": float(t[i + 1]),
                        "direction": "left_to_right" if d[i] > 0 else "right_to_left", "before": before, "after": after})  # fmt: skip
    return sorted(out, key=lambda c: (c["t_s"], c["obj"]))


def _independent_run(t: np.ndarray, side: np.ndarray, i: int, step: int, gap_s: float, tc_s: float) -> int:
    """How many positions ``tc_s`` apart the run of same-side evidence from ``i`` (going back, ``step`` −1, or on) holds."""
    kept, last, j = 0, None, i
    while 0 <= j < len(t) and side[j] == side[i] and (j == i or abs(t[j] - t[j - step]) <= gap_s):
        if last is None or abs(t[j] - last) >= tc_s:
            kept, last = kept + 1, t[j]
        j += step
    return kept


def unproven_crossings(net: CityNetwork, paths: pd.DataFrame, proven: list[dict], rows: pd.DataFrame,
                       gap_s: float = CROSSING_GAP_S) -> list[dict]:  # fmt: skip
    """The raw path's crossings that no proven crossing covers, each with why it is not proven."""
    out = []
    last: dict[int, tuple[float, dict]] = {}  # per gantry, its last path crossing listed: a noisy path zigzags across a line
    for p in paths.sort_values(["t_s", "obj"], kind="stable").itertuples(index=False):
        if p.gap_s > OUTAGE_MAX_S or any(c["obj"] == p.obj and c["from_s"] - gap_s <= p.t_s <= c["to_s"] + gap_s for c in proven):
            continue
        if p.obj in last and p.t_s - last[p.obj][0] <= gap_s:
            last[p.obj] = (p.t_s, last[p.obj][1])
            last[p.obj][1]["path_crossings"] += 1
            continue
        near = rows[(rows["obj"] == p.obj) & (np.abs(rows["t_s"] - p.t_s) <= gap_s)]
        statuses = {str(s): int(n) for s, n in near["status"].value_counts().sort_index().items()}
        if p.gap_s > gap_s:
            why = (f"no position for {p.gap_s:.0f} s around the line (more than {gap_s:g} s): the crossing is not proven by "
                   f"positions on both sides")  # fmt: skip
        elif not near["valid"].any():
            why = "no valid position near the line (see statuses)"
        else:
            sides = set(np.sign(near.loc[near["evidence"], "distance_m"]))
            missing = [name for name, s in (("left", 1.0), ("right", -1.0)) if s not in sides]
            why = (f"no valid position whose bound stays clear of the line on its {' and '.join(missing)} side within {gap_s:g} s"
                   if missing else f"the evidence on the two sides is more than {gap_s:g} s apart")  # fmt: skip
        out.append({"obj": int(p.obj), "t_s": float(p.t_s), "direction": p.direction, "why": why, "statuses": statuses, "path_crossings": 1})
        last[p.obj] = (p.t_s, out[-1])
    return out


def presences(net: CityNetwork, rows: pd.DataFrame, tc_s: float, n_th: int, gap_s: float = PRESENCE_GAP_S) -> tuple[list[dict], list[dict]]:
    """Zone presences proven by evidence, and the raw stays inside a zone that are not (with their statuses)."""
    proven, unproven = [], []
    for k, group in rows.groupby("obj", sort=True):
        if net.kinds[k] != "zone":
            continue
        g = group.sort_values("t_s", kind="stable")
        inside = g[g["distance_m"] > -np.inf]
        runs = _runs(inside["t_s"].to_numpy(float), gap_s)
        for lo, hi in runs:
            stay = inside.iloc[lo:hi]
            ev = stay[stay["evidence"]]
            t_ev = ev["t_s"].to_numpy(float)
            kept = np.flatnonzero(thin_independent(t_ev, np.zeros(t_ev.size, np.int64), np.ones(t_ev.size, bool), tc_s))
            if len(kept) >= n_th:
                proven.append({"obj": int(k), "from_s": float(stay["t_s"].iat[0]), "to_s": float(stay["t_s"].iat[-1]),
                               "evidence": ev.iloc[kept]})  # fmt: skip
            elif (stay["distance_m"] > 0).any():
                statuses = {str(s): int(n) for s, n in stay["status"].value_counts().sort_index().items()}
                unproven.append({"obj": int(k), "t_s": float(stay["t_s"].iat[0]), "to_s": float(stay["t_s"].iat[-1]),
                                 "why": f"{len(kept)} independent valid positions whose bound stays inside the zone; {n_th} needed",
                                 "statuses": statuses})  # fmt: skip
    return proven, unproven


def _runs(t: np.ndarray, gap_s: float) -> list[tuple[int, int]]:
    if not len(t):
        return []
    cuts = np.flatnonzero(np.diff(t) > gap_s) + 1
    starts = np.r_[0, cuts]
    ends = np.r_[cuts, len(t)]
    return list(zip(starts.tolist(), ends.tolist()))
