"""Tamper and evasion findings for one trip, each with times, positions and the evidence behind it.

Categories and kinds (thresholds are :class:`FindingSettings` fields, recorded with the findings):

evasion
  ``gap``  the log stops and starts again far away (≥ ``gap_min_s`` and ≥ ``gap_min_m``): the
  geo-objects on the straight line between the two fixes, and those inside the reachable ellipse
  (foci the two fixes, major axis ``max_speed_mps`` × duration), are listed as possibly driven,
  not charged.
jamming
  ``cn0_collapse``  the median and the 80th percentile C/N0 of the tracked satellites both fall
  ≥ ``cn0_drop_db`` below their median over the previous ``baseline_s`` (all satellites together);
  ``satellite_collapse``  satellites tracked fall to ≤ half of that baseline (and by ≥ 3) for ≥ 2 epochs,
  and the fix goes with them (lost, or fewer than 4 satellites used; a receiver still fixing on ≥ 4
  satellites has a short satellite report, not a collapse);
  ``fix_lost_at_speed``  the log goes on without a fix for ≥ ``fix_loss_min_s`` right after moving
  at ≥ ``fix_loss_speed_mps``.
spoofing
  ``position_jump``  consecutive fixes ≤ 5 s apart imply a speed above the vehicle's ``max_speed_mps``;
  ``time_jump``  time runs backwards, or jumps ≥ ``time_jump_s`` forward while a moving vehicle stays put;
  ``overspeed``  reported speed above ``max_speed_mps`` for ≥ 3 epochs;
  ``cn0_uniform``  ≥ 5 satellites with C/N0 spread < ``uniform_std_db`` and median ≥ ``uniform_min_dbhz``
  for ≥ ``uniform_min_s`` (a simulator's signature);
  ``raim_persistent_alarm``  the RAIM's test fails in ≥ 80 % of ≥ ``raim_window_s`` s (one epoch a second) with good
  geometry (HDOP ≤ 2, ≥ 6 satellites), far more often than those epochs' P_FA explain (binomial tail
  < ``RAIM_ALARM_P_VALUE``: ETC alarms at P_FA near 1 — probable false alarms — accuse nobody);
  ``position_disagreement``  two sentences of one epoch place it ≥ ``disagree_m`` apart (GGA vs RMC…);
  ``date_disagreement``  ZDA and RMC give different dates;
  ``date_jump``  inside a continuous trip an RMC/ZDA date jumps away from the trip's date (the epochs keep
  the trip's date, so the passage is charged once; ``week_rollover`` when the jump is a multiple of
  1024 GPS weeks, a receiver fault rather than an attack);
  ``doppler_mismatch``  over ``doppler_window_s`` s the fixes' displacement and the one the reported (Doppler)
  velocity gives differ by more than max(``doppler_tol_mps``, 30 %) as speeds, for ≥ ``doppler_window_s`` s
  (a time window, whatever the rate: :func:`doppler_windows`).
  ``osnma_failure``  Galileo OSNMA refused a satellite's navigation data, a key or a signature (``osnma_failures.py``:
  from the log's navigation pages, not from these epochs).
expected
  ``tunnel_outage``  a gap, fix loss or collapse at a geo-object's tunnel, no longer than the tunnel takes
  (``tunnels.py``; ``tunnel_portal_m``, ``tunnel_reacquire_s``): the kind it replaces is in ``evidence.explains``.

Why this file is long: one short function per kind of finding over one shared table of fixes; split by
category they would each rebuild that table.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
import shapely
from shapely import affinity

from tollcli.enforcement.trip import cn0_summary, fixes, runs, trailing_median
from tollcli.enforcement.tunnels import tunnel_outages
from tollcli.errors import UsageError
from tollcli.geodesy import great_circle_distance_m
from tollcli.stats import binomial_tail
from tollcli.times import epoch_seconds, iso_from_seconds

CATEGORY = {
    "gap": "evasion", "cn0_collapse": "jamming", "satellite_collapse": "jamming", "fix_lost_at_speed": "jamming",
    "position_jump": "spoofing", "time_jump": "spoofing", "overspeed": "spoofing", "cn0_uniform": "spoofing",
    "raim_persistent_alarm": "spoofing", "position_disagreement": "spoofing", "date_disagreement": "spoofing",
    "date_jump": "spoofing",
    "doppler_mismatch": "spoofing", "osnma_failure": "spoofing", "tunnel_outage": "expected",
}  # fmt: skip
#: a persistent RAIM alarm is reported when no-fault alarms (each epoch at its own P_FA) would be this unlikely
RAIM_ALARM_P_VALUE = 1e-3
#: 1024 GPS weeks, days (a receiver that counts weeks modulo 1024 dates fixes this far back)
WEEK_ROLLOVER_DAYS = 1024 * 7
#: top speed by vehicle class, m/s (a vehicle faster than this is not that vehicle, or not where it says)
CLASS_MAX_SPEED_MPS = {"car": 250 / 3.6, "van": 180 / 3.6, "truck": 130 / 3.6, "bus": 130 / 3.6, "motorcycle": 300 / 3.6}


@dataclass(frozen=True)
class FindingSettings:
    max_speed_mps: float = 250 / 3.6
    gap_min_s: float = 60.0
    gap_min_m: float = 500.0
    tunnel_portal_m: float = 50.0
    tunnel_reacquire_s: float = 60.0
    baseline_s: float = 30.0
    cn0_drop_db: float = 8.0
    fix_loss_min_s: float = 10.0
    fix_loss_speed_mps: float = 8.0
    time_jump_s: float = 300.0
    uniform_std_db: float = 1.0
    uniform_min_dbhz: float = 45.0
    uniform_min_s: float = 10.0
    raim_window_s: float = 30.0
    disagree_m: float = 50.0
    doppler_tol_mps: float = 3.0
    doppler_window_s: float = 10.0

    @classmethod
    def for_class(cls, vehicle_class: str, **overrides) -> "FindingSettings":
        """The settings of a vehicle class (its top speed); an unknown class is an error unless the top speed is given."""
        if "max_speed_mps" in overrides:
            return cls(**overrides)
        if vehicle_class not in CLASS_MAX_SPEED_MPS:
            raise UsageError(f"unknown vehicle class {vehicle_class!r}: one of {', '.join(CLASS_MAX_SPEED_MPS)} "
                             "(or give its top speed, --max-speed)")  # fmt: skip
        return cls(max_speed_mps=CLASS_MAX_SPEED_MPS[vehicle_class], **overrides)


def _finding(kind: str, rows: tuple[int, int], t0: float, t1: float, lat0, lon0, lat1=None, lon1=None, **evidence) -> dict:
    """One finding; ``rows``: its first and last epoch rows (kept under ``_rows`` for streaming, not written)."""
    r = lambda v: None if v is None or not np.isfinite(v) else round(float(v), 7)  # noqa: E731
    clean = {k: ((round(float(v), 3) if np.isfinite(v) else None) if isinstance(v, (float, np.floating))
                 else (int(v) if isinstance(v, np.integer) else v)) for k, v in evidence.items()}  # fmt: skip
    return {"kind": kind, "category": CATEGORY[kind], "start_utc": iso_from_seconds(t0), "end_utc": iso_from_seconds(t1),
            "lat_deg": r(lat0), "lon_deg": r(lon0), "end_lat_deg": r(lat1), "end_lon_deg": r(lon1), "evidence": clean,
            "_rows": (int(rows[0]), int(rows[1]))}  # fmt: skip


def trip_findings(epochs: pd.DataFrame, satellites: pd.DataFrame | None = None, raim: pd.DataFrame | None = None,
                  geo=None, settings: FindingSettings = FindingSettings(), cn0: pd.DataFrame | None = None,
                  keep_rows: bool = False, times_increase: bool | None = None) -> list[dict]:  # fmt: skip
    """All findings of one trip, in time order. ``raim``: per-epoch RAIM columns (same rows as ``epochs``).

    ``cn0``: the per-epoch C/N0 summary (:func:`~tollcli.enforcement.trip.cn0_summary`) when the
    satellite table itself is not kept (a long log read in chunks). ``keep_rows``: each finding keeps
    its first and last epoch rows under ``_rows`` (for the streaming charge, :mod:`tollcli.job.streaming`).
    ``times_increase``: whether the trailing baselines may use time windows (default: the times of
    ``epochs`` are all known and never go back). Epochs a trajectory placed (``--positioning``) are judged at their
    snapshot fixes (``snapshot_lat_deg``/``snapshot_lon_deg``): a jump or a gap the receiver's own positions show is
    evidence, whatever the smoothed trajectory made of it.
    """
    epochs = epochs.reset_index(drop=True)
    if epochs.empty:
        return []
    if "snapshot_lat_deg" in epochs:  # a trajectory placed the epochs: the findings read what the receiver measured
        epochs = epochs.assign(lat_deg=epochs["snapshot_lat_deg"], lon_deg=epochs["snapshot_lon_deg"])
    fill = {c: np.nan for c in ("speed_mps", "hdop") if c not in epochs}  # pseudorange inputs have no NMEA extras
    fill.update({c: -1 for c in ("line",) if c not in epochs})
    if "epoch" not in epochs:
        fill["epoch"] = np.arange(len(epochs))
    epochs = epochs.assign(**fill) if fill else epochs
    t = epoch_seconds(epochs)
    fx = fixes(epochs, t)
    out: list[dict] = []
    out += _gaps(fx, geo, settings)
    out += _jumps(fx, settings)
    out += _time_jumps(epochs, t, settings)
    out += _speed_checks(epochs, t, fx, settings)
    summary = cn0 if cn0 is not None else cn0_summary(satellites, len(epochs), int(epochs["epoch"].iat[0]))
    out += _cn0_checks(epochs, summary, t, fx, settings, times_increase)
    out += _fix_loss(epochs, t, fx, settings)
    out += _disagreements(epochs, t)
    if raim is not None:
        out += _raim_alarm(epochs, raim.reset_index(drop=True), t, settings)
    out = tunnel_outages(out, geo, settings.tunnel_portal_m, settings.tunnel_reacquire_s)
    out.sort(key=lambda f: (f["start_utc"], f["kind"]))
    if not keep_rows:
        for f in out:
            del f["_rows"]
    return out


def _where(epochs: pd.DataFrame, row: int) -> tuple[float, float]:
    return float(epochs["lat_deg"].iat[row]), float(epochs["lon_deg"].iat[row])


def _gaps(fx, geo, s: FindingSettings) -> list[dict]:
    hit = np.flatnonzero((fx.dt_s >= s.gap_min_s) & (fx.step_m >= s.gap_min_m))
    out = []
    for i in hit:  # one per gap (a few per trip), not per epoch
        line_ids, reach_ids = _crossable(geo, fx.lat_deg[i], fx.lon_deg[i], fx.lat_deg[i + 1], fx.lon_deg[i + 1],
                                         s.max_speed_mps * fx.dt_s[i])  # fmt: skip
        out.append(_finding("gap", (fx.rows[i], fx.rows[i + 1]), fx.t_s[i], fx.t_s[i + 1], fx.lat_deg[i], fx.lon_deg[i], fx.lat_deg[i + 1], fx.lon_deg[i + 1],
                            duration_s=fx.dt_s[i], distance_m=fx.step_m[i], implied_speed_mps=fx.step_m[i] / fx.dt_s[i],
                            geoobjects_on_line=line_ids, geoobjects_reachable=reach_ids,
                            note="possibly driven, not charged"))  # fmt: skip
    return out


def _crossable(geo, lat0, lon0, lat1, lon1, reach_m: float) -> tuple[list[str], list[str]]:
    """Geo-objects crossed by the straight line, and those inside the reachable ellipse (not on the line)."""
    if geo is None:
        return [], []
    from tollcli.spatial import wgs84_to

    tr = wgs84_to(geo.crs)
    (x0, x1), (y0, y1) = tr.transform([lon0, lon1], [lat0, lat1])
    line = shapely.LineString([(x0, y0), (x1, y1)])
    on_line = sorted(str(geo.ids[i]) for i in geo.index.query(line, predicate="intersects"))
    c = line.length / 2.0
    a = max(reach_m / 2.0, c)
    b = np.sqrt(max(a * a - c * c, 0.0))
    ellipse = affinity.scale(shapely.Point(0, 0).buffer(1.0, quad_segs=32), a, max(b, 1.0))
    ellipse = affinity.rotate(ellipse, np.degrees(np.arctan2(y1 - y0, x1 - x0)), origin=(0, 0))
    ellipse = affinity.translate(ellipse, (x0 + x1) / 2, (y0 + y1) / 2)
    reach = sorted(str(geo.ids[i]) for i in geo.index.query(ellipse, predicate="intersects"))
    return on_line, [g for g in reach if g not in on_line]


def _jumps(fx, s: FindingSettings) -> list[dict]:
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = fx.step_m / fx.dt_s
    hit = np.flatnonzero((fx.dt_s > 0) & (fx.dt_s <= 5.0) & (speed > s.max_speed_mps) & (fx.step_m > 50.0))
    return [_finding("position_jump", (fx.rows[i], fx.rows[i + 1]), fx.t_s[i], fx.t_s[i + 1], fx.lat_deg[i], fx.lon_deg[i], fx.lat_deg[i + 1], fx.lon_deg[i + 1],
                     distance_m=fx.step_m[i], dt_s=fx.dt_s[i], implied_speed_mps=speed[i], max_speed_mps=s.max_speed_mps)
            for i in hit]  # fmt: skip


def _time_jumps(epochs: pd.DataFrame, t: np.ndarray, s: FindingSettings) -> list[dict]:
    out = []
    dt = np.diff(t)
    back = np.flatnonzero(dt < -0.5)
    for i in back:
        lat, lon = _where(epochs, i + 1)
        out.append(_finding("time_jump", (i, i + 1), t[i], t[i + 1], lat, lon, step_s=dt[i], line=int(epochs["line"].iat[i + 1]),
                            direction="backwards"))  # fmt: skip
    speed = epochs["speed_mps"].to_numpy(float)
    lat, lon = epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float)
    moved = great_circle_distance_m(lat[:-1], lon[:-1], lat[1:], lon[1:])
    fast = (speed[:-1] > 5.0) & (speed[1:] > 5.0)
    with np.errstate(invalid="ignore"):
        stay = moved < 5.0 * np.maximum(speed[:-1], 1.0)  # no further than a few seconds of driving
    for i in np.flatnonzero((dt >= s.time_jump_s) & fast & stay):
        out.append(_finding("time_jump", (i, i + 1), t[i], t[i + 1], lat[i], lon[i], lat[i + 1], lon[i + 1], step_s=dt[i], distance_m=moved[i],
                            speed_mps=speed[i], direction="forward while moving in place"))  # fmt: skip
    return out


def _speed_checks(epochs: pd.DataFrame, t: np.ndarray, fx, s: FindingSettings) -> list[dict]:
    out = []
    speed = epochs["speed_mps"].to_numpy(float)
    for a, b in runs(speed > s.max_speed_mps):
        if b - a + 1 >= 3:
            lat, lon = _where(epochs, a)
            out.append(_finding("overspeed", (a, b), t[a], t[b], lat, lon, max_reported_mps=np.nanmax(speed[a : b + 1]),
                                max_speed_mps=s.max_speed_mps, epochs=b - a + 1))  # fmt: skip
    return out + _doppler_checks(epochs, fx, t, s)


#: steps longer than this break a Doppler window (a gap is another finding's business)
DOPPLER_MAX_STEP_S = 2.0


def doppler_windows(epochs: pd.DataFrame, fx, window_s: float) -> dict[str, np.ndarray]:
    """Over the last ``window_s`` seconds before each fix: the displacement of the fixes and the one the reported
    velocity (speed over ground and course, dead-reckoned, trapezoid) gives, as speeds in m/s, and the speed of
    their difference. The displacement, not the path length: at 5–20 Hz the path of noisy short steps is
    longer than the road. Where a course is missing the reported path length stands in for its displacement
    (on a bend it is longer: the check is then looser, never falsely alarmed by the bend).

    Returns per fix: ``start`` (the window's first fix, −1 when there is none), ``position_speed_mps``,
    ``reported_speed_mps``, ``difference_mps`` (NaN where the window has a gap or a missing speed)."""
    m = fx.rows.size
    nan = np.full(m, np.nan)
    speed = epochs["speed_mps"].to_numpy(float)[fx.rows]
    course = epochs["course_deg"].to_numpy(float)[fx.rows] if "course_deg" in epochs else nan
    start = np.searchsorted(fx.t_s, fx.t_s - window_s, side="right") - 1
    if m < 2:
        return {"start": np.full(m, -1), "position_speed_mps": nan, "reported_speed_mps": nan, "difference_mps": nan}
    v = (speed[:-1] + speed[1:]) / 2.0
    rad = np.radians(course)
    ce, cn = np.sin(rad[:-1]) + np.sin(rad[1:]), np.cos(rad[:-1]) + np.cos(rad[1:])
    norm = np.hypot(ce, cn)
    with np.errstate(invalid="ignore", divide="ignore"):
        ue, un = ce / norm, cn / norm
    has_course = np.isfinite(ue) & np.isfinite(un)
    step_ok = (fx.dt_s > 0) & (fx.dt_s <= DOPPLER_MAX_STEP_S) & np.isfinite(v)
    d = np.where(step_ok, v * fx.dt_s, 0.0)

    def window_sum(x: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(x)])
        j = np.arange(m)
        return np.where(start >= 0, c[j] - c[np.maximum(start, 0)], np.nan)

    bad_steps = window_sum((~step_ok).astype(float))
    no_course = window_sum((~has_course).astype(float))
    dr_e, dr_n = window_sum(np.where(has_course, d * ue, 0.0)), window_sum(np.where(has_course, d * un, 0.0))
    path = window_sum(d)
    i = np.maximum(start, 0)
    span = fx.t_s - fx.t_s[i]
    lat0 = np.radians((fx.lat_deg + fx.lat_deg[i]) / 2)
    pn = np.radians(fx.lat_deg - fx.lat_deg[i]) * 6_371_008.8
    pe = np.radians(fx.lon_deg - fx.lon_deg[i]) * 6_371_008.8 * np.cos(lat0)
    usable = (start >= 0) & (start < np.arange(m)) & (bad_steps == 0) & (span >= window_s * 0.5)
    with np.errstate(invalid="ignore", divide="ignore"):
        pos = np.where(usable, np.hypot(pe, pn) / span, np.nan)
        vectors = no_course == 0
        rep = np.where(usable, np.where(vectors, np.hypot(dr_e, dr_n), path) / span, np.nan)
        diff = np.where(vectors, np.hypot(pe - dr_e, pn - dr_n) / span, np.abs(pos - rep))
    return {"start": np.where(usable, start, -1), "position_speed_mps": pos, "reported_speed_mps": rep,
            "difference_mps": np.where(usable, diff, np.nan)}  # fmt: skip


def _doppler_checks(epochs: pd.DataFrame, fx, t: np.ndarray, s: FindingSettings) -> list[dict]:
    """``doppler_mismatch``: the fixes' displacement and the reported velocity's disagree by more than
    max(``doppler_tol_mps``, 30 %) over every ``doppler_window_s`` window for at least ``doppler_window_s``."""
    out = []
    if fx.rows.size < 3 or "speed_mps" not in epochs:
        return out
    w = doppler_windows(epochs, fx, s.doppler_window_s)
    mp, mr = w["position_speed_mps"], w["reported_speed_mps"]
    with np.errstate(invalid="ignore"):
        flag = w["difference_mps"] > np.maximum(s.doppler_tol_mps, 0.3 * np.maximum(mp, mr))
    step = float(np.median(fx.dt_s[fx.dt_s > 0])) if np.any(fx.dt_s > 0) else 1.0
    for a, b in runs(flag):
        if fx.t_s[b] - fx.t_s[a] + step >= s.doppler_window_s:
            r0, r1 = fx.rows[a], fx.rows[b]
            seg = slice(a, b + 1)
            out.append(_finding("doppler_mismatch", (r0, r1), t[r0], t[r1], fx.lat_deg[a], fx.lon_deg[a], fx.lat_deg[b], fx.lon_deg[b],
                                reported_speed_mps=np.nanmean(mr[seg]), position_speed_mps=np.nanmean(mp[seg]),
                                window_s=s.doppler_window_s))  # fmt: skip
    return out


def _cn0_checks(epochs: pd.DataFrame, summary: pd.DataFrame, t: np.ndarray, fx, s: FindingSettings,
                times_increase: bool | None = None) -> list[dict]:  # fmt: skip
    """Jamming and spoofing signs in the per-epoch C/N0 summary (:func:`~tollcli.enforcement.trip.cn0_summary`)."""
    out = []
    n = summary["n_tracked"].to_numpy(float)
    # an epoch with a fix but no satellite report is the receiver's GSV cadence (or a time-only
    # sentence), not a loss of satellites: unknown, not zero
    has_fix = np.zeros(len(epochs), bool)
    has_fix[fx.rows] = True
    n = np.where((n == 0) & has_fix, np.nan, n)
    med, p80, std = (summary[c].to_numpy(float) for c in ("cn0_median", "cn0_p80", "cn0_std"))
    if not np.isfinite(med).any():
        return out
    base_med, base_p80, base_n = trailing_median(np.column_stack([med, p80, n]), t, s.baseline_s, times_increase).T
    with np.errstate(invalid="ignore"):
        dropped = (base_med - med >= s.cn0_drop_db) & (base_p80 - p80 >= s.cn0_drop_db)
        # a satellite count collapse: the count falls to half (or to none) of its recent median
        collapsed = (base_n >= 4) & (n <= base_n / 2) & (base_n - n >= 3)
        # a receiver that keeps ≥ 4 satellites in its fix has not lost them: its satellite report is short
        col = "n_used_receiver" if "n_used_receiver" in epochs else "n_used"  # the receiver's own count (GSA/GGA)
        used = epochs[col].to_numpy(float) if col in epochs else np.full(len(epochs), np.nan)
        collapsed &= ~(has_fix & (used >= 4))
    collapsed = collapsed & _at_least(collapsed, 2)
    for kind, flag in (("cn0_collapse", dropped), ("satellite_collapse", collapsed)):
        for a, b in _held(flag, med if kind == "cn0_collapse" else n, base_med if kind == "cn0_collapse" else base_n,
                          s.cn0_drop_db / 2 if kind == "cn0_collapse" else None):
            if b - a + 1 >= 2:
                lat, lon = _where(epochs, a)
                out.append(_finding(kind, (a, b), t[a], t[b], lat, lon, baseline_cn0_dbhz=base_med[a], cn0_dbhz=np.nanmin(med[a : b + 1]) if np.isfinite(med[a : b + 1]).any() else None,
                                    baseline_tracked=base_n[a], tracked=int(np.nanmin(n[a : b + 1])) if np.isfinite(n[a : b + 1]).any() else None,
                                    epochs=b - a + 1))  # fmt: skip
    with np.errstate(invalid="ignore"):
        uniform = (n >= 5) & (std < s.uniform_std_db) & (med >= s.uniform_min_dbhz)
    for a, b in runs(uniform):
        if t[b] - t[a] >= s.uniform_min_s:
            lat, lon = _where(epochs, a)
            out.append(_finding("cn0_uniform", (a, b), t[a], t[b], lat, lon, cn0_median_dbhz=np.nanmedian(med[a : b + 1]),
                                cn0_spread_db=np.nanmax(std[a : b + 1]), satellites=int(np.median(n[a : b + 1]))))  # fmt: skip
    return out


def _at_least(flag: np.ndarray, n: int) -> np.ndarray:
    """Keep only the runs of ``flag`` that last at least ``n`` epochs."""
    keep = np.zeros(flag.size, bool)
    for a, b in runs(flag):
        if b - a + 1 >= n:
            keep[a : b + 1] = True
    return keep


def _held(flag: np.ndarray, value: np.ndarray, baseline: np.ndarray, margin: float | None) -> list[tuple[int, int]]:
    """Runs of ``flag``, each extended while ``value`` stays below the baseline it started from.

    The trailing baseline soon learns a long episode; holding the onset's baseline keeps
    the finding open until the signal recovers (C/N0 within ``margin`` dB of it; a count
    back above half of it). Runs that the extension joins are merged.
    """
    out: list[tuple[int, int]] = []
    for a, b in runs(flag):
        if out and a <= out[-1][1]:
            continue
        ref = baseline[a]
        with np.errstate(invalid="ignore"):
            low = (value[a:] <= ref - margin) | ~np.isfinite(value[a:]) if margin is not None else value[a:] <= ref / 2
        end = a + (int(np.argmin(low)) - 1 if not low.all() else low.size - 1)
        out.append((a, max(b, end)))
    return out


def _fix_loss(epochs: pd.DataFrame, t: np.ndarray, fx, s: FindingSettings) -> list[dict]:
    out = []
    has_fix = np.zeros(len(epochs), bool)
    has_fix[fx.rows] = True
    speed = epochs["speed_mps"].to_numpy(float)
    for a, b in runs(~has_fix):
        if a == 0:
            continue  # the log starts without a fix: a cold start, not a loss
        last = fx.rows[fx.rows < a]
        if last.size == 0:
            continue
        before = speed[last[-1]]
        end_t = t[b + 1] if b + 1 < len(t) else t[b]
        if end_t - t[last[-1]] >= s.fix_loss_min_s and np.isfinite(before) and before >= s.fix_loss_speed_mps:
            lat, lon = _where(epochs, last[-1])
            out.append(_finding("fix_lost_at_speed", (last[-1], min(b + 1, len(t) - 1)), t[last[-1]], end_t, lat, lon, speed_before_mps=before,
                                duration_s=end_t - t[last[-1]], epochs_without_fix=b - a + 1))  # fmt: skip
    return out


def _disagreements(epochs: pd.DataFrame, t: np.ndarray) -> list[dict]:
    out = []
    if "pos_disagreement_m" in epochs:
        gap = epochs["pos_disagreement_m"].to_numpy(float)
        with np.errstate(invalid="ignore"):
            flag = gap >= FindingSettings.disagree_m
        for a, b in runs(flag):
            lat, lon = _where(epochs, a)
            out.append(_finding("position_disagreement", (a, b), t[a], t[b], lat, lon, max_disagreement_m=np.nanmax(gap[a : b + 1]), epochs=b - a + 1))
    if "date_disagreement_days" in epochs:
        days = epochs["date_disagreement_days"].to_numpy(float)
        for a, b in runs(np.isfinite(days) & (days != 0)):
            lat, lon = _where(epochs, a)
            out.append(_finding("date_disagreement", (a, b), t[a], t[b], lat, lon, zda_minus_rmc_days=days[a], epochs=b - a + 1))
    if "date_jump_days" in epochs:
        jumps = epochs["date_jump_days"].to_numpy(float)
        for a, b in runs(np.isfinite(jumps)):
            lat, lon = _where(epochs, a)
            out.append(_finding("date_jump", (a, b), t[a], t[b], lat, lon, given_minus_trip_days=jumps[a],
                                week_rollover=bool(jumps[a] % WEEK_ROLLOVER_DAYS == 0), epochs=b - a + 1))  # fmt: skip
    return out


def once_a_second(t_s: np.ndarray) -> np.ndarray:
    """Rows of the first epoch in each second (all rows when the times do not increase): the RAIM's alarms at 5–20 Hz
    are no more independent than the errors behind them, which last seconds; one a second is what 1 Hz logs give."""
    t = np.asarray(t_s, float)
    if t.size == 0 or not (np.isfinite(t).all() and np.all(np.diff(t) >= 0)):
        return np.arange(t.size)
    sec = np.floor(t + 1e-6)
    return np.flatnonzero(np.r_[True, sec[1:] != sec[:-1]])


def _raim_alarm(epochs: pd.DataFrame, raim: pd.DataFrame, t: np.ndarray, s: FindingSettings) -> list[dict]:
    status_all = raim["raim_status"].astype(str).to_numpy()
    sample = once_a_second(t)  # windows of raim_window_s seconds, one epoch a second, whatever the rate
    status = status_all[sample]
    monitored = np.isin(status, ["valid", "fault_detected", "excluded_valid", "probable_false_alarm"])
    # every failed test counts, but a window needs far more alarms than its P_FA explain (ETC's at P_FA ≈ 1 do not)
    alarm_kinds = ["fault_detected", "probable_false_alarm"] if "p_fa" in raim else ["fault_detected"]
    alarm = np.isin(status, alarm_kinds)
    hdop = epochs["hdop"].to_numpy(float)[sample]
    n_used = raim["n_used"].to_numpy(float)[sample]
    good = monitored & (hdop <= 2.0) & (n_used >= 6)
    n = max(int(s.raim_window_s), 2)
    c_good = np.concatenate([[0], np.cumsum(good)])
    c_alarm = np.concatenate([[0], np.cumsum(alarm & good)])
    p_fa_all = np.nan_to_num(raim["p_fa"].to_numpy(float), nan=1.0) if "p_fa" in raim else np.zeros(len(raim))
    p_fa = p_fa_all[sample]
    c_p_fa = np.concatenate([[0.0], np.cumsum(np.where(good, np.clip(p_fa, 0.0, 1.0), 0.0))])
    idx = np.arange(n, good.size + 1)
    if idx.size == 0:
        return []
    g = c_good[idx] - c_good[idx - n]
    alarms = c_alarm[idx] - c_alarm[idx - n]
    share = np.where(g > 0, alarms / np.maximum(g, 1), 0.0)
    expected = np.where(g > 0, (c_p_fa[idx] - c_p_fa[idx - n]) / np.maximum(g, 1), 1.0)
    candidate = np.flatnonzero((g >= 0.8 * n) & (share >= 0.8))
    surprise = binomial_tail(alarms[candidate], g[candidate], expected[candidate])  # P(≥ this many alarms | no fault)
    hot = idx[candidate[surprise < RAIM_ALARM_P_VALUE]]
    mark = np.zeros(good.size + 1)
    np.add.at(mark, hot - n, 1)  # every sampled epoch of a hot window
    np.add.at(mark, hot, -1)
    flag_sampled = np.cumsum(mark)[:-1] > 0
    ends = np.append(sample[1:], len(epochs)) - 1  # a sampled epoch stands for its second
    flag = np.zeros(len(epochs), bool)
    for a, b in runs(flag_sampled):
        flag[sample[a] : ends[b] + 1] = True
    alarm, p_fa, hdop = np.isin(status_all, alarm_kinds), p_fa_all, epochs["hdop"].to_numpy(float)
    out = []
    for a, b in runs(flag):
        lat, lon = _where(epochs, a)
        out.append(_finding("raim_persistent_alarm", (a, b), t[a], t[b], lat, lon, alarm_share=float(np.mean(alarm[a : b + 1])),
                            expected_false_alarm_share=float(np.mean(np.clip(p_fa[a : b + 1], 0.0, 1.0))),
                            **_alarm_statistic(raim, a, b), median_hdop=float(np.nanmedian(hdop[a : b + 1]))))  # fmt: skip
    return out


def _alarm_statistic(raim: pd.DataFrame, a: int, b: int) -> dict:
    """What a window's alarms were tested with: the statistic, the receiver output it came from and its median against
    the threshold it was tested against — a test statistic against its χ² threshold, or (solution separation, whose
    threshold is per subset) the largest separation over its threshold, which alarms above 1."""
    rows = slice(a, b + 1)
    out = {"median_test_stat": _nanmedian(raim["test_stat"].to_numpy(float)[rows])}
    if "test_stat_source" in raim:
        sources = raim["test_stat_source"].astype(str).to_numpy()[rows]
        sources = sources[(sources != "none") & (sources != "<NA>") & (sources != "")]
        if sources.size:
            names, counts = np.unique(sources, return_counts=True)
            out["statistic_source"] = str(names[np.argmax(counts)])  # the receiver output the residuals came from
    threshold = _nanmedian(raim["threshold"].to_numpy(float)[rows])
    if np.isfinite(threshold) or "separation_ratio" not in raim:
        return {**out, "statistic": "test_stat", "median_threshold": threshold}
    return {**out, "statistic": "separation_ratio", "median_separation_ratio": _nanmedian(raim["separation_ratio"].to_numpy(float)[rows]),
            "median_threshold": 1.0}  # fmt: skip


def _nanmedian(values: np.ndarray) -> float:
    """The median of the finite values (NaN, without a warning, when there are none)."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else float("nan")


def settings_dict(settings: FindingSettings) -> dict:
    return asdict(settings)
