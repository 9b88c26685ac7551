"""Geo-object recognition: which tolled segments a trip really used (paper 001 §II, thesis eq. 3.6).

For every epoch with a position, candidate geo-objects come from a spatial index
in the geo-objects' metric CRS (bulk ``STRtree.query``). A position counts for a
geo-object when it lies inside it **and** is valid under that geo-object's own
HAL: for the ETC RAIM the threshold depends on HAL, so the RAIM runs per
(epoch, candidate geo-object) pair. After an exclusion the shifted position must
still be inside. On a geo-object that is one of two opposite carriageways the
course must also agree with its direction of travel (``carriageways.py``).

Positions inside one geo-object are grouped into passages (a new passage after
``passage_gap_s`` without a fix inside; in a geo-object with a tunnel, or of several parts, after that plus
the time its tunnel and the longest stretch between its parts take at ``tollcli.geoobjects.store.TUNNEL_MIN_SPEED_MPS``: no
GNSS reaches a tunnel, no geo-object covers a stretch cut around another road, and the fixes before and after are
one passage, charged once). In each passage the valid positions are
thinned to independent ones, at least ``tc_s`` apart (greedy from the first:
exact), and the geo-object is charged when N_valid,in ≥ ``n_th``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import shapely

from tollcli.errors import DataError
from tollcli.gnss.measurements import Measurements
from tollcli.gnss.wls import Geometry, take_epochs
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import HalFreeTerms, run_raim

VALID_STATUSES = ("valid", "excluded_valid")
#: a position inside whose vouched position (the RAIM's own solution, after any exclusion) lies outside the geo-object:
#: trusted, but not here — its own status, so that a passage's statuses add up to its valid count
VALID_OUTSIDE = "valid_outside"
PASSAGE_GAP_S = 120.0


def passage_gaps_s(geo, passage_gap_s: float = PASSAGE_GAP_S) -> np.ndarray:
    """Per geo-object: the longest time without a fix inside that still continues a passage, s."""
    return passage_gap_s + geo.gap_times_s()


from tollcli.geoobjects.store import GeoObjects, load_geoobjects  # noqa: E402,F401  (re-exported)


def warm_up(geo: GeoObjects) -> None:
    """Make this thread's transformer into the geo-objects' search CRS now (the first one loads PROJ's database,
    ~0.1–0.2 s): done while a reading thread reads the log's first chunk, it is off the charge's path."""
    from tollcli.spatial import wgs84_to

    if geo is not None and getattr(geo, "crs", None) and len(geo.ids):
        wgs84_to(geo.crs)


def candidate_pairs(epochs: pd.DataFrame, geo: GeoObjects) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(epoch row, geo-object index) for every position inside a geo-object, and per pair the position's metric x, y
    in that geo-object's own frame (the bounding boxes are found in the file's search CRS)."""
    from tollcli.spatial import wgs84_to

    lon, lat = epochs["lon_deg"].to_numpy(float), epochs["lat_deg"].to_numpy(float)
    x, y = wgs84_to(geo.crs).transform(lon, lat)
    x, y = np.asarray(x, float), np.asarray(y, float)
    have = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    # the boxes hit, then the exact test on coordinates: the same pairs as predicate="within", without a geometry per point
    hit, obj = geo.index.query(shapely.points(x[have], y[have]))
    rows = have[hit]
    px, py = x[rows], y[rows]
    if geo.frame is not None and not (len(geo.frames) == 1 and geo.frames[0] == geo.crs):
        frame = geo.frame[obj]
        for k in np.unique(frame):  # one transform per frame met (a few), not per position
            sel = frame == k
            fx, fy = wgs84_to(geo.frames[k]).transform(lon[rows[sel]], lat[rows[sel]])
            px[sel], py[sel] = fx, fy
    inside = shapely.contains_xy(geo.polygons[obj], px, py)
    rows, obj, px, py = rows[inside], obj[inside], px[inside], py[inside]
    order = np.lexsort((obj, rows))
    return rows[order], obj[order], px[order], py[order]


def utc_seconds(time_utc: pd.Series) -> np.ndarray:
    """A tz-aware UTC column → float seconds since 1970 (DataError if any time is missing)."""
    if time_utc.isna().any():
        raise DataError("some epochs have no date (a log without RMC/ZDA): give --date")
    return utc_seconds_or_nan(time_utc.array)


def utc_seconds_or_nan(times) -> np.ndarray:
    """tz-aware UTC times → float seconds since 1970 at millisecond resolution (NaN for a missing time)."""
    if not len(times):
        return np.zeros(0)
    ms = pd.DatetimeIndex(times).tz_convert(None).to_numpy().astype("datetime64[ms]").astype(np.int64) / 1000.0
    missing = pd.isna(times)
    return np.where(missing, np.nan, ms) if np.any(missing) else ms


def recognise(epochs: pd.DataFrame, meas: Measurements, geo: GeoObjects, params: RaimParams,
              tc_s: float = 5.0, n_th: int = 1, passage_gap_s: float = PASSAGE_GAP_S,
              epoch_why: np.ndarray | None = None, checks: pd.DataFrame | None = None) -> pd.DataFrame:  # fmt: skip
    """One row per (epoch, geo-object) position inside, with its RAIM verdict under that HAL.

    Columns: ``epoch_row``, ``geoobject``, ``time_utc``, ``passage`` (per geo-object),
    ``raim_status``, ``test_stat``, ``threshold``, ``p_fa``, ``test_stat_source``, ``integrity_source``
    (the source whose verdict decided, :mod:`tollcli.integrity.sources`),
    ``valid`` (counts for the geo-object), ``independent`` (kept by T_c thinning), ``verdict``
    (the RAIM status, or for a RAIM-valid position the fault a check found: ``epoch_why`` per
    epoch row, '' when none; ``checks``, per epoch row, the policy's check columns: :func:`pair_verdicts`),
    ``confirmed_by`` and ``not_checked`` (with ``checks``).

    Two steps, so that a long log can run the first chunk by chunk: :func:`inside_pairs`
    (the RAIM under each geo-object's HAL, per epoch inside it) and :func:`positions_from_pairs`.
    """
    pairs = inside_pairs(epochs, meas, geo, params)
    return positions_from_pairs(pairs, epochs["time_utc"], geo, tc_s, passage_gap_s, epoch_why, checks)


PAIR_COLUMNS = ("epoch_row", "obj", "raim_status", "test_stat", "threshold", "p_fa", "test_stat_source", "integrity_source",
                "raim_valid")  # fmt: skip
#: ``direction``: '' or why a carriageway does not count the position (wrong_direction, direction_unknown)
#: ``hpl_m`` / ``separation_ratio``: the bound a position was declared against and its largest separation (NaN: none)
#: ``part``: which polygon of a geo-object of several parts holds the position (0-based; 0 for one part)
OPTIONAL_PAIR_COLUMNS = ("direction", "hpl_m", "separation_ratio", "part")


def inside_pairs(epochs: pd.DataFrame, meas: Measurements, geo: GeoObjects, params: RaimParams, row_offset: int = 0,
                 geometry: Geometry | None = None, environment: str = "auto",
                 hal_free: HalFreeTerms | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """Every (epoch, geo-object) with the position inside, and the RAIM verdict under that geo-object's HAL.

    ``raim_valid``: RAIM-valid and, after an exclusion, the shifted position still inside.
    ``row_offset`` is added to the epoch rows (for a chunk of a longer log). ``geometry``:
    the WLS geometry of ``meas`` when the caller has it (the same for every HAL); ``hal_free``: its solution
    separation and model HPL (:func:`~tollcli.integrity.run.hal_free_terms` with ``params``' probabilities: the
    same for every HAL too). Where a geo-object declares the
    environment its road runs in (``geo.environment``), the ``model`` level takes that environment's σ for the
    positions inside it that no residual measured (``environment``: the ``--environment`` given, which a declaration
    never weakens: :func:`~tollcli.integrity.environment.with_declared_environment`).
    """
    rows, obj, px, py = candidate_pairs(epochs, geo)
    if rows.size == 0:
        return {"epoch_row": np.zeros(0, np.int64), "obj": np.zeros(0, np.int64), "raim_status": np.zeros(0, object),
                "test_stat": np.zeros(0), "threshold": np.zeros(0), "p_fa": np.zeros(0), "hpl_m": np.zeros(0),
                "separation_ratio": np.zeros(0),
                "test_stat_source": np.zeros(0, object), "integrity_source": np.zeros(0, object),
                "raim_valid": np.zeros(0, bool), "direction": np.zeros(0, object), "part": np.zeros(0, np.int64)}  # fmt: skip
    taken = inside = meas.take(rows)
    if geo.environment is not None:
        from tollcli.integrity.environment import with_declared_environment

        inside = with_declared_environment(inside, geo.environment[obj], environment)
    terms = hal_free.take(rows, model=inside is taken) if hal_free is not None else None  # a declared σ: its own model HPL
    raim = run_raim(inside, params, hal_m=geo.hal_m[obj], geometry=take_epochs(geometry, rows) if geometry is not None else None,
                    hal_free=terms)  # fmt: skip
    status = raim["raim_status"].to_numpy(dtype=object)
    # the position the RAIM vouches for: its own weighted solution, after any exclusion
    de = raim["fde_shift_e_m"].to_numpy() + raim["wls_shift_e_m"].to_numpy()
    dn = raim["fde_shift_n_m"].to_numpy() + raim["wls_shift_n_m"].to_numpy()
    moved = np.flatnonzero((de != 0) | (dn != 0))  # an unshifted position is inside: it is a candidate pair
    shifted_inside = np.ones(rows.size, bool)
    shifted_inside[moved] = shapely.contains_xy(geo.polygons[obj[moved]], px[moved] + de[moved], py[moved] + dn[moved])
    return {"epoch_row": rows + row_offset, "obj": obj, "raim_status": status, "test_stat": raim["test_stat"].to_numpy(),
            "threshold": raim["threshold"].to_numpy(), "p_fa": raim["p_fa"].to_numpy(), "hpl_m": raim["hpl_m"].to_numpy(),
            "separation_ratio": raim["separation_ratio"].to_numpy(),
            "test_stat_source": raim["test_stat_source"].to_numpy(dtype=object),
            "integrity_source": raim["integrity_source"].to_numpy(dtype=object),
            "raim_valid": np.isin(status, VALID_STATUSES) & shifted_inside,
            "direction": _directions(epochs, geo, rows, obj, px, py), "part": parts_of(geo, obj, px, py)}  # fmt: skip


def parts_of(geo: GeoObjects, obj: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Per position inside a geo-object: the index of its part (polygon) that holds it, 0 for a one-part geo-object."""
    out = np.zeros(obj.size, np.int64)
    n_parts = geo.n_parts[obj]
    multi = np.flatnonzero(n_parts > 1)
    for k in range(1, int(n_parts.max(initial=1))):  # a few parts at most: one vectorized test per part number
        sel = multi[n_parts[multi] > k]
        inside = shapely.contains_xy(shapely.get_geometry(geo.polygons[obj[sel]], k), px[sel], py[sel])
        out[sel[inside]] = k
    return out


def _directions(epochs: pd.DataFrame, geo: GeoObjects, rows: np.ndarray, obj: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Per pair: '' or why a carriageway does not count the position (``carriageways.direction_check``)."""
    out = np.full(rows.size, "", dtype=object)
    directed = geo.directed()[obj]
    if directed.any():
        from tollcli.geoobjects.carriageways import direction_check

        nan = np.full(len(epochs), np.nan)
        course = epochs["course_deg"].to_numpy(float) if "course_deg" in epochs else nan
        speed = epochs["speed_mps"].to_numpy(float) if "speed_mps" in epochs else nan
        out[directed] = direction_check(geo.axes[obj[directed]], px[directed], py[directed], course[rows[directed]],
                                        speed[rows[directed]])  # fmt: skip
    return out


def concat_pairs(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([p[k] for p in parts]) for k in (*PAIR_COLUMNS, *OPTIONAL_PAIR_COLUMNS) if k in parts[0]} if parts else {}


def positions_from_pairs(pairs: dict[str, np.ndarray], time_utc: pd.Series, geo: GeoObjects, tc_s: float = 5.0,
                         passage_gap_s: float = PASSAGE_GAP_S, epoch_why: np.ndarray | None = None,
                         checks: pd.DataFrame | None = None) -> pd.DataFrame:  # fmt: skip
    """The positions table of :func:`recognise` from :func:`inside_pairs` (``time_utc``: of every epoch row)."""
    if not pairs or pairs["epoch_row"].size == 0:
        return empty_positions()
    rows = pairs["epoch_row"]
    verdicts = pair_verdicts(pairs, geo, epoch_why, checks)
    return passages({**pairs, **verdicts, "t_s": utc_seconds(time_utc)[rows], "time_utc": time_utc.array[rows]}, geo, tc_s,
                    passage_gap_s)  # fmt: skip


POSITION_COLUMNS = ("epoch_row", "geoobject", "time_utc", "passage", "raim_status", "test_stat", "threshold", "p_fa",
                    "hpl_m", "separation_ratio", "test_stat_source", "integrity_source", "valid", "independent", "verdict")  # fmt: skip


def empty_positions() -> pd.DataFrame:
    return pd.DataFrame(columns=list(POSITION_COLUMNS))


def pair_verdicts(pairs: dict[str, np.ndarray], geo: GeoObjects, epoch_why: np.ndarray | None = None,
                  checks: pd.DataFrame | None = None, row_offset: int = 0) -> dict[str, np.ndarray]:  # fmt: skip
    """Per pair: whether it counts (``valid``), its verdict (the RAIM status, or the fault a check found), and with
    ``checks`` the checks that confirmed it (``confirmed_by``: '', ``speed``, ``map_matching`` or both joined by
    '+') and why the others did not check (``not_checked``: '' or statuses joined by '+').

    ``epoch_why``: per epoch, '' or the fault an epoch-level check found (``speed_inconsistent``, an unauthenticated
    position under --require-authenticated). ``checks``: per epoch, the policy's check columns — ``speed_status``
    for the speed check, ``matched_road``/``mm_status``/``match_dist_m`` for map matching, whose veto depends on
    the geo-object (:func:`tollcli.integrity.verdict.map_matching_pair_checks`; the pairs' ``geo_road`` is each
    geo-object's road in the network, ``geo_road_dist_m`` the position's distance to it). Both are indexed by epoch row − ``row_offset``.
    """
    from tollcli.integrity.speed import SPEED_NOT_CHECKED
    from tollcli.integrity.verdict import map_matching_pair_checks

    rows, obj = pairs["epoch_row"] - row_offset, pairs["obj"]
    valid = pairs["raim_valid"].copy()
    verdict = pairs["raim_status"].copy()
    # a position the RAIM vouched for only after moving it (its own solution, an exclusion) outside the geo-object
    verdict[np.isin(verdict, VALID_STATUSES) & ~valid] = VALID_OUTSIDE
    if "direction" in pairs:  # a carriageway counts a position only in its direction of travel
        # travelling against it is the other carriageway whatever the RAIM says (the revenue at risk must not count
        # it); an unknown direction only matters where the position would count
        against = pairs["direction"] == "wrong_direction"
        wrong = against | (valid & (pairs["direction"] != ""))
        verdict[wrong] = pairs["direction"][wrong]
        valid &= ~wrong
    if epoch_why is not None:
        why = np.asarray(epoch_why, dtype=object)[rows]
        fails = valid & (why != "")
        verdict[fails] = why[fails]
        valid &= ~fails
    out = {"valid": valid, "verdict": verdict}
    if checks is None:
        return out
    confirmed = [np.full(rows.size, "", dtype=object)]
    not_checked = []
    if "matched_road" in checks:
        hal = geo.hal_m[obj]
        hpl = pairs.get("hpl_m", np.full(rows.size, np.nan))
        bound = np.where(np.isfinite(hpl), hpl, hal)
        dist = pairs.get("geo_road_dist_m", np.full(rows.size, np.nan))
        veto, mm_ok, mm_not = map_matching_pair_checks(
            pairs.get("geo_road", geo.ids[obj]), checks["matched_road"].to_numpy(object)[rows], checks["mm_status"].to_numpy(object)[rows],
            checks["match_dist_m"].to_numpy(float)[rows], dist, bound)  # fmt: skip
        fails = valid & (veto != "")
        verdict[fails] = veto[fails]
        valid &= ~fails
        confirmed.append(np.where(mm_ok, "map_matching", ""))
        not_checked.append(mm_not)
    if "speed_status" in checks:
        speed = checks["speed_status"].to_numpy(object).astype(str)[rows]
        confirmed.append(np.where(speed == "ok", "speed", ""))
        not_checked.append(np.where(np.isin(speed, SPEED_NOT_CHECKED), np.char.add("speed_", speed), ""))
    out.update(confirmed_by=_joined(confirmed), not_checked=_joined(not_checked))
    return out


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """Per row, the non-empty strings of ``parts`` joined by '+' ('' when none)."""
    if not parts:
        return np.zeros(0, dtype=object)
    out = np.full(np.asarray(parts[0]).shape, "", dtype=object)
    for part in parts:
        part = np.asarray(part, dtype=object)
        both = (out != "") & (part != "")
        out = np.where(both, out + "+" + part, np.where(part != "", part, out)).astype(object)
    return out


def passages(cols: dict[str, np.ndarray], geo: GeoObjects, tc_s: float = 5.0, passage_gap_s: float = PASSAGE_GAP_S,
             first_passage: int = 0) -> pd.DataFrame:  # fmt: skip
    """Positions (pair columns with ``valid``, ``verdict``, ``t_s``, ``time_utc``) grouped into passages and thinned.

    Passages: consecutive inside fixes of one geo-object at most ``passage_gap_s`` apart (plus its tunnel's
    time, :func:`passage_gaps_s`), numbered
    from ``first_passage`` in (geo-object, time) order. Rows come out in that order.
    """
    by_obj = np.lexsort((cols["t_s"], cols["obj"]))
    obj, t_s, valid = cols["obj"][by_obj], cols["t_s"][by_obj], cols["valid"][by_obj]
    new = np.ones(obj.size, dtype=bool)
    new[1:] = (obj[1:] != obj[:-1]) | (np.diff(t_s) > passage_gaps_s(geo, passage_gap_s)[obj[1:]])
    passage = np.cumsum(new) - 1 + first_passage
    independent = thin_independent(t_s, passage, valid, tc_s)
    return pd.DataFrame({
        "epoch_row": cols["epoch_row"][by_obj], "geoobject": geo.ids[obj], "time_utc": cols["time_utc"][by_obj],
        "passage": passage, "raim_status": cols["raim_status"][by_obj], "test_stat": cols["test_stat"][by_obj],
        "threshold": cols["threshold"][by_obj], "p_fa": cols["p_fa"][by_obj],
        "hpl_m": cols.get("hpl_m", np.full(obj.size, np.nan))[by_obj],
        "separation_ratio": cols.get("separation_ratio", np.full(obj.size, np.nan))[by_obj],
        "test_stat_source": cols["test_stat_source"][by_obj], "integrity_source": cols["integrity_source"][by_obj],
        "valid": valid, "independent": independent,
        "verdict": cols["verdict"][by_obj],
        **({"part": cols["part"][by_obj]} if "part" in cols else {}),
        **({"nav_auth": cols["nav_auth"][by_obj]} if "nav_auth" in cols else {}),
        **{k: cols[k][by_obj] for k in ("confirmed_by", "not_checked") if k in cols},
    })  # fmt: skip


def thin_independent(t_s: np.ndarray, group: np.ndarray, valid: np.ndarray, tc_s: float) -> np.ndarray:
    """Greedy T_c thinning per group: keep the first valid time, then each next one ≥ T_c after the last kept.

    Rows must be sorted by (group, time). Vectorized: every valid row gets a pointer
    to the first valid row of its group at least T_c later; the kept rows are the
    chain of pointers from each group's first valid row (one step per kept position).
    """
    keep = np.zeros(t_s.size, dtype=bool)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return keep
    g, t = group[idx], t_s[idx] - t_s[idx].min()
    key = g * (t.max() + 2 * tc_s + 1.0) + t  # groups one after another on one axis, times kept exact
    nxt = np.searchsorted(key, key + tc_s - 1e-9, side="left")
    nxt = np.maximum(nxt, np.arange(idx.size) + 1)  # always a step forward: the chain ends whatever T_c
    nxt = np.where((nxt < idx.size) & (g[np.minimum(nxt, idx.size - 1)] == g), nxt, -1)
    first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    cur = first
    while cur.size:
        keep[idx[cur]] = True
        cur = nxt[cur]
        cur = cur[cur >= 0]
    return keep


def charges(positions: pd.DataFrame, n_th: int) -> pd.DataFrame:
    """Per (geo-object, passage): entry/exit times, counts, and whether it is charged (N_valid,in ≥ N_Th)."""
    if positions.empty:
        return pd.DataFrame(columns=["geoobject", "passage", "entry_utc", "exit_utc", "n_inside", "n_valid",
                                     "n_independent", "charged"])  # fmt: skip
    out = _charges_in_order(positions)
    if out is None:
        grouped = positions.groupby(["geoobject", "passage"], sort=False)
        out = grouped.agg(entry_utc=("time_utc", "min"), exit_utc=("time_utc", "max"), n_inside=("valid", "size"),
                          n_valid=("valid", "sum"), n_independent=("independent", "sum")).reset_index()  # fmt: skip
    out["charged"] = out["n_independent"] >= n_th
    if "part" in positions:  # which parts of a geo-object of several the passage went through (1-based)
        out["parts_seen"] = _parts_seen(positions, out)
    return out.sort_values(["entry_utc", "geoobject"], kind="stable").reset_index(drop=True)


def _parts_seen(positions: pd.DataFrame, out: pd.DataFrame) -> list[tuple[int, ...]]:
    """Per row of ``out`` (a geo-object's passage): the parts (1-based, increasing) its positions were in."""
    keys = pd.MultiIndex.from_arrays([out["geoobject"].to_numpy(dtype=object), out["passage"].to_numpy()])
    row = keys.get_indexer(pd.MultiIndex.from_arrays([positions["geoobject"].to_numpy(dtype=object),
                                                      positions["passage"].to_numpy()]))  # fmt: skip
    part = positions["part"].to_numpy(np.int64)
    width = int(part.max(initial=0)) + 1
    pair = np.unique(row[row >= 0].astype(np.int64) * width + part[row >= 0])  # (row, part), by row then part
    rows, parts = pair // width, (pair % width + 1).tolist()
    counts = np.bincount(rows, minlength=len(out))
    if (counts == 1).all():  # one part each (the usual geo-object): no splitting
        return [(v,) for v in parts]
    ends = np.cumsum(counts).tolist()
    return [tuple(parts[a:b]) for a, b in zip([0, *ends[:-1]], ends)]


def _charges_in_order(positions: pd.DataFrame) -> pd.DataFrame | None:
    """The grouping of :func:`charges` without pandas' groupby, for positions in passage order (as
    :func:`passages` gives them: each passage's rows together, passages increasing); None otherwise."""
    passage = positions["passage"].to_numpy()
    gid = positions["geoobject"].to_numpy(dtype=object)
    times = positions["time_utc"].array
    if passage.dtype.kind not in "iu" or not isinstance(times, pd.arrays.DatetimeArray) or times.isna().any():
        return None
    edge = np.r_[True, (passage[1:] != passage[:-1]) | (gid[1:] != gid[:-1])]
    start = np.flatnonzero(edge)
    if np.any(np.diff(passage[start]) <= 0):  # a passage number in two places: leave it to groupby
        return None
    group = np.cumsum(edge) - 1
    order = np.lexsort((times.asi8, group))  # each group's earliest first, latest last
    first = np.searchsorted(group[order], np.arange(start.size), side="left")
    last = np.r_[first[1:], order.size] - 1
    sums = lambda c: np.add.reduceat(positions[c].to_numpy(bool).astype(np.int64), start)  # noqa: E731
    return pd.DataFrame({
        "geoobject": gid[start], "passage": passage[start], "entry_utc": times.take(order[first]),
        "exit_utc": times.take(order[last]), "n_inside": np.diff(np.r_[start, passage.size]).astype(np.int64),
        "n_valid": sums("valid"), "n_independent": sums("independent"),
    })  # fmt: skip
