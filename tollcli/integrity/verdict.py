"""One verdict per epoch from the three checks — RAIM, speed, map matching — under a named policy.

Map-matching integrity per epoch (Binjammaz 2015 §4.2.3) over the last ``mm_window`` intervals:
ΔD = |D_map − D_GPS| (metres: the distance between consecutive matched points against the distance
between consecutive raw fixes, summed over the window), ΔS = |D_map/T − average Doppler speed|
(km/h), Δθ from the matching; the Sugeno scale of :mod:`tollcli.integrity.fuzzy_mm`; ``mm_status``
``ok`` (scale ≥ 71), ``alarm``, or ``unmatched`` (no road within reach).

Policies (``--policy``): which checks may veto a position that counts in charging.

=============  ==========================================================================
``raim``       the RAIM verdict only
``raim+speed`` and the speed check's fault verdict (``speed_inconsistent``)
``raim+mm``    and map matching's fault verdicts (``mm_off_road``, ``mm_other_road``)
``all``        all three (the default when the log has speeds and a road network is given)
=============  ==========================================================================

**A check vetoes only on evidence of a fault.** The speed check vetoes a position whose positions disagree
with the Doppler velocity (:mod:`tollcli.integrity.speed`); a slow, stopped, accelerating or turning vehicle
is not checked (``speed_low_speed``, ``speed_unavailable``, ``speed_no_data``) and keeps the RAIM's verdict.
Map matching vetoes where its matching is trusted (fuzzy scale ≥ 71) and the position's own bound (its HPL,
else the geo-object's HAL, plus ``ROAD_HALF_WIDTH_M`` for lanes) excludes a road: ``mm_off_road`` — the road
the matching holds (topology: the vehicle cannot have left it) lies beyond the bound, the position jumped off
the network; ``mm_other_road`` — the matching holds another road and the geo-object's own road lies beyond
the bound. An alarm of the fuzzy scale (``mm_alarm``: the matching is not trusted, e.g. at a join between
two segments of one street), no road within reach (``mm_unmatched``) and another road while the geo-object's
road is within the bound (``mm_nearby_road``: the next segment at a join) are not checked.

Where a check passes it **confirms** the position: ``speed`` (consistent at ≥ 2 m/s), ``map_matching``
(trusted match onto the geo-object's own road, within the bound). The invoice lists, per passage, the
checks that confirmed its evidence and why the others did not check.

The default is the strictest **fault detection** the inputs support: ``all`` with speeds and roads,
``raim+speed`` with speeds only, else ``raim`` (map matching reads speed and heading).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.integrity.fuzzy_mm import alarm, integrity_scale
from tollcli.integrity.map_matching import (
    MatchParams,
    MatchState,
    MatchTrace,
    Roads,
    match_with_trace,
)
from tollcli.integrity.speed import SPEED_FAULTS, SpeedParams, speed_integrity, trapezoid_average

POLICIES = {"raim": (), "raim+speed": ("speed",), "raim+mm": ("mm",), "all": ("speed", "mm")}


def default_policy(has_speed: bool, has_roads: bool) -> str:
    """The strictest policy the inputs support: the speed check needs a speed over ground, and so does map
    matching (its fuzzy rules read speed and heading); without them a road network adds no check."""
    if not has_speed:
        return "raim"
    return "all" if has_roads else "raim+speed"


def mm_integrity(epochs: pd.DataFrame, matched: pd.DataFrame, window: int = 5, ramp: float = 0.0) -> pd.DataFrame:
    """ΔD, ΔS, the fuzzy scale, its level and the status per epoch (columns of the module docstring)."""
    from tollcli.geodesy import great_circle_distance_m
    from tollcli.times import epoch_seconds

    n = len(epochs)
    lat, lon = epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float)
    step_gps = np.r_[np.nan, great_circle_distance_m(lat[:-1], lon[:-1], lat[1:], lon[1:])] if n else np.zeros(0)
    mx, my = matched["matched_x_m"].to_numpy(float), matched["matched_y_m"].to_numpy(float)
    step_map = np.r_[np.nan, np.hypot(np.diff(mx), np.diff(my))] if n else np.zeros(0)
    c_g = np.concatenate([[0.0], np.cumsum(np.nan_to_num(step_gps))])
    c_m = np.concatenate([[0.0], np.cumsum(np.nan_to_num(step_map))])
    c_ok = np.concatenate([[0], np.cumsum(np.isfinite(step_gps) & np.isfinite(step_map))])
    t = epoch_seconds(epochs)
    d_gps = np.full(n, np.nan)
    d_map = np.full(n, np.nan)
    span = np.full(n, np.nan)
    if n > window:
        end = np.arange(window, n)
        full = (c_ok[end + 1] - c_ok[end + 1 - window]) == window
        d_gps[end] = np.where(full, c_g[end + 1] - c_g[end + 1 - window], np.nan)
        d_map[end] = np.where(full, c_m[end + 1] - c_m[end + 1 - window], np.nan)
        span[end] = t[end] - t[end - window]
    speed = epochs["speed_mps"].to_numpy(float) if "speed_mps" in epochs else np.full(n, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        delta_d = np.abs(d_map - d_gps)
        delta_s_kmh = np.abs(d_map / span - trapezoid_average(speed, window)) * 3.6
    scale, level, rule = integrity_scale(matched["delta_theta_deg"].to_numpy(float), delta_d, delta_s_kmh, ramp)
    unmatched = matched["matched_road"].astype(str).to_numpy() == ""
    status = np.where(unmatched, "unmatched", np.where(alarm(scale), "alarm", "ok"))
    return pd.DataFrame({"delta_d_m": delta_d, "delta_s_kmh": delta_s_kmh, "mm_integrity": scale,
                         "mm_level": pd.array(level, dtype="string"), "mm_rule": rule,
                         "mm_status": pd.array(status, dtype="string")})  # fmt: skip


def epoch_checks(epochs: pd.DataFrame, roads: Roads | None, speed_params: SpeedParams = SpeedParams(),
                 match_params: MatchParams = MatchParams(), mm_window: int = 5) -> pd.DataFrame:  # fmt: skip
    """The speed and map-matching columns for every epoch (map matching only with ``roads``)."""
    return epoch_checks_traced(epochs, roads, speed_params, match_params, mm_window)[0]


def epoch_checks_traced(epochs: pd.DataFrame, roads: Roads | None, speed_params: SpeedParams = SpeedParams(),
                        match_params: MatchParams = MatchParams(), mm_window: int = 5, step_s: float | None = None,
                        match_state: MatchState = MatchState()) -> tuple[pd.DataFrame, MatchTrace | None]:  # fmt: skip
    """:func:`epoch_checks` for a stretch of a log: the epoch interval given (``step_s``), the matching
    started in ``match_state``, and its trace (None without roads)."""
    out = speed_integrity(epochs, speed_params, step_s=step_s)
    trace = None
    if roads is not None:
        trusted = epochs["raim_status"].astype(str).isin(["valid", "excluded_valid"]).to_numpy() if "raim_status" in epochs else None
        matched, trace = match_with_trace(epochs, roads, match_params, trusted, match_state)
        out = pd.concat([out, matched, mm_integrity(epochs, matched, mm_window)], axis=1)
    return out, trace


def failed_check(checks: pd.DataFrame, policy: str) -> np.ndarray:
    """Per epoch, the epoch-level check that found a fault under the policy ('' when none did): the speed check's
    ``speed_inconsistent``. Map matching's faults depend on the geo-object (:func:`map_matching_pair_checks`)."""
    why = np.full(len(checks), "", dtype=object)
    if "speed" in POLICIES[policy]:
        s = checks["speed_status"].astype(str).to_numpy()
        why = np.where(np.isin(s, SPEED_FAULTS), "speed_" + s, why)
    return why


#: how far a vehicle on a road may be from the road's line: lanes, a carriageway's width (m)
ROAD_HALF_WIDTH_M = 7.5
#: what map matching's not-checked and fault verdicts mean (the invoice's notes)
MM_MEANINGS = {
    "mm_off_road": ("map matching holds the vehicle on a road (it cannot have left it: no connecting road) that lies "
                    "further from the position than the position's bound allows: the position jumped off the road "
                    "network, a position fault; not charged on"),
    "mm_other_road": ("map matching holds the vehicle on another road, and the geo-object's road lies further from the "
                      "position than the position's bound allows: the vehicle was not on it; not charged on"),
    "mm_alarm": ("not checked: map matching did not trust its own match here (fuzzy integrity below 71, e.g. at a join "
                 "between two segments of one street); the RAIM's verdict stands"),
    "mm_unmatched": "not checked: no road of the network within reach; the RAIM's verdict stands",
    "mm_nearby_road": ("not checked: map matching holds another road (e.g. the next segment at a join) but the "
                       "geo-object's road is within the position's bound; the RAIM's verdict stands"),
}  # fmt: skip


def map_matching_pair_checks(geo_road: np.ndarray, matched_road: np.ndarray, mm_status: np.ndarray, match_dist_m: np.ndarray,
                             geo_road_dist_m: np.ndarray, bound_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Per (position, geo-object): map matching's veto ('' or ``mm_off_road``/``mm_other_road``), whether it confirms
    the position, and why it did not check ('' or ``mm_alarm``/``mm_unmatched``/``mm_nearby_road``).

    ``geo_road``: the geo-object's road in the network ('' when none); ``bound_m``: the position's bound (its HPL for
    that geo-object's HAL); ``geo_road_dist_m``: the position's distance to the geo-object's road (NaN where the
    network has none: no ``mm_other_road``)."""
    geo_road = np.asarray(geo_road, dtype=object).astype(str)
    road = np.asarray(matched_road, dtype=object).astype(str)
    status = np.asarray(mm_status, dtype=object).astype(str)
    reach = np.asarray(bound_m, float) + ROAD_HALF_WIDTH_M
    trusted = status == "ok"
    same = (road == geo_road) & (geo_road != "")
    with np.errstate(invalid="ignore"):
        off = trusted & (np.asarray(match_dist_m, float) > reach)
        other = trusted & ~off & ~same & (np.asarray(geo_road_dist_m, float) > reach)
    veto = np.where(off, "mm_off_road", np.where(other, "mm_other_road", "")).astype(object)
    confirmed = trusted & ~off & same
    why_not = np.where(status == "unmatched", "mm_unmatched", np.where(~trusted, "mm_alarm", "mm_nearby_road"))
    not_checked = np.where((veto == "") & ~confirmed, why_not, "").astype(object)
    return veto, confirmed, not_checked
