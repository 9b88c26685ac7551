"""``tollcli info``: what a receiver log or a geo-object file holds, before anything is charged on it.

For a log: its kind (as ``--input-format auto`` recognises it), its messages (NMEA sentence types, UBX
messages, gpsd report classes, GnssLogger records …), and — for the receivers' own solutions (NMEA, u-blox NAV,
gpsd JSON, RTKLIB) — the epochs, their span and rate, the fixes by quality, the evidence each integrity source
needs (residuals, the receiver's RAIM, its error ellipse, satellites) and so the level ``--integrity-sources
auto`` would settle on. For a geo-object file: :func:`tollcli.geoobjects.info.geoobject_info`.
"""

from __future__ import annotations

import os
from collections import Counter

import numpy as np

from tollcli.errors import DataError
from tollcli.io.log_run import LogRun
from tollcli.job.distance_driven import DistanceCarry, add_distance, distance_from
from tollcli.readers.log_contents import message_counts
from tollcli.readers.navigation import NAVIGATION_KINDS, iter_navigation_tables
from tollcli.readers.nmea import ReadStats

#: what each pseudorange kind needs besides the log to be solved
NEEDS = {"rinex": "a navigation file (--nav) for an observation file", "gnsslogger": "a navigation file (--nav)",
         "ubx": "RXM-SFRBX navigation data in the log, or --nav", "device-gnss": "", "gsdc-derived": "", "librsf": ""}
UNKNOWN_HINT = ("no NMEA sentence nor any other kind tollcli reads; a binary protocol gpsd decodes (SiRF, GREIS, "
                "Oncore, …) is read through gpsd's gpsdecode: tollcli runs it where it is installed (Debian: gpsd-clients), "
                "or pipe: gpsdecode < FILE | tollcli integrity -")
#: the integrity levels, strictest first, and the evidence each needs
LEVEL_EVIDENCE = (("residual", "residuals"), ("receiver", "receiver_raim"), ("covariance", "error_ellipse"),
                  ("model", "satellites"))


def _is_json_doc(path: str) -> dict | None:
    """The JSON document in ``path`` when it is one (a geo-object file, an invoice), else None."""
    if path == "-" or not path.lower().endswith((".json", ".geojson")):
        return None
    from tollcli.io.sources import read_json

    doc = read_json(path, "a JSON document")
    return doc if isinstance(doc, dict) else None


def file_info(path: str, min_hal_m: float = 25.0, nav: str | list[str] | None = None) -> dict:
    """What ``path`` holds, as a JSON-ready dict (see the module's description)."""
    from tollcli.geoobjects.info import geoobject_info

    if path != "-" and path.lower().endswith((".json", ".geojson")):
        try:  # read feature by feature: a national network's file is never parsed whole
            return {"file": path, "kind": "geoobjects", **geoobject_info(path, min_hal_m)}
        except DataError:
            pass  # no FeatureCollection (an invoice?): read as a document below
    doc = _is_json_doc(path)
    if doc is not None and doc.get("type") == "FeatureCollection":  # one geoobject_info refused: say why
        return {"file": path, "kind": "geoobjects", **geoobject_info(path, min_hal_m)}
    if doc is not None and "content_sha256" in doc and "lines" in doc:
        return {"file": path, "kind": "invoice", "vehicle": doc.get("vehicle"), "period": doc.get("period"),
                "charged": len(doc["lines"]), "not_charged": len(doc.get("not_charged") or []),
                "total": doc.get("total"), "currency": doc.get("currency"), "inputs": doc.get("inputs"),
                "integrity_sources_used": (doc.get("parameters") or {}).get("integrity_sources_used")}
    with LogRun(path) as run:  # the log opened once: counted and read from the same copy of its bytes
        kind = run.kind
        try:
            replay = run.replay_path()
        except DataError as exc:  # a binary protocol gpsdecode reads nothing of: what info says, not an error of info's
            if not run.decoded_by:
                raise
            return {"file": path, "kind": "gpsd-binary", "decoded_by": run.decoded_by, "messages": {}, "problem": str(exc),
                    "bytes": os.path.getsize(path) if path != "-" and os.path.isfile(path) else run.bytes_stored}  # fmt: skip
        out: dict = {"file": path, "kind": kind,
                     "bytes": os.path.getsize(path) if path != "-" and os.path.isfile(path) else run.bytes_stored}  # fmt: skip
        if run.decoded_by:  # a binary protocol, read as gpsd reports it
            out.update(kind="gpsd-binary", decoded_by=run.decoded_by)
        with run.named_errors():
            out["messages"] = message_counts(replay, kind)
        if kind == "nmea" and not out["messages"]:  # what is nothing else is read as NMEA: here there is none
            return {**out, "kind": "unknown", "needs": UNKNOWN_HINT}
        if kind in NAVIGATION_KINDS:
            try:
                with run.named_errors():
                    out.update(_solution_info(replay, kind))
            except DataError as exc:  # nothing to read: what info says, not an error of info's
                out.update(epochs=0, problem=str(exc))
        elif kind != "unknown":
            out["solved_by"] = "tollcli (pseudoranges: WLS, then the RAIM on their residuals)"
            out["needs"] = NEEDS.get(kind, "")
            out["integrity_level"] = "residual"
            with run.named_errors():
                out.update(_pseudorange_info(replay, kind, nav, out["messages"], run.name))
        if out.get("first_problem"):
            out["first_problem"] = run.named(out["first_problem"])
    return out


def _pseudorange_info(path: str, kind: str, nav, messages: dict, name: str) -> dict:
    """Epochs, span, box and distance of a pseudorange log, from its snapshot positions; where they cannot be solved
    (no orbits), why — and for a u-blox log that also holds the receiver's own solutions, those (what ``process``
    charges then)."""
    from tollcli.errors import UsageError
    from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
    from tollcli.gnss.sigma_models import NominalModel
    from tollcli.integrity.trajectory import with_trajectory

    try:
        epochs, meas = pseudorange_epochs(path, kind, nav, "nominal", 5.0, NominalModel())
    except (DataError, UsageError) as exc:
        out = {"positions": f"not solved: {str(exc).replace(path, name)}"}
        solutions = receiver_solutions(messages) if kind == "ubx" and nav is None else []
        if solutions:
            out.update(_solution_info(path, "ubx-nav"))
            out["positions"] += f"; the receiver's own solutions ({', '.join(solutions)}) are read instead"
        return out
    t = epochs["time_utc"].dropna()
    first, last = (t.min(), t.max()) if len(t) else (None, None)
    steps = np.diff(t.to_numpy("datetime64[ms]").astype(np.int64)) / 1000.0 if len(t) > 1 else np.zeros(0)
    positive = steps[steps > 0]
    interval = float(np.median(positive)) if positive.size else None
    lat, lon = epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float)
    with_position = int((np.isfinite(lat) & np.isfinite(lon)).sum())
    placed, _, positioning = with_trajectory(epochs, meas, "auto")  # where process charges it from
    distance = DistanceCarry()
    t_s = (placed["time_utc"] - placed["time_utc"].iloc[0]).dt.total_seconds().to_numpy(float) if len(placed) else np.zeros(0)
    lat, lon = placed["lat_deg"].to_numpy(float), placed["lon_deg"].to_numpy(float)
    add_distance(distance, t_s, lat, lon, placed["speed_mps"].to_numpy(float) if "speed_mps" in placed else None)
    source = distance_from(distance, "fixes" if positioning == "snapshot" else f"the {positioning} trajectory")
    return {"epochs": len(epochs), "epochs_with_position": with_position,
            "first_utc": _iso(first), "last_utc": _iso(last),
            "span_s": round((last - first).total_seconds(), 3) if first is not None else None,
            "interval_s": round(interval, 3) if interval else None, "rate_hz": round(1.0 / interval, 3) if interval else None,
            **track_extent(lat, lon), "distance_m": round(distance.distance_m, 1), "distance_from": source,
            "clock": "seconds from the start (no date)" if kind == "librsf" else "GPS time",
            "skipped_lines": int(epochs.attrs.get("skipped_lines", 0))}  # fmt: skip


#: the u-blox messages that carry the receiver's own position solution
SOLUTION_MESSAGES = ("NAV-PVT", "NAV-SOL", "NAV-POSLLH", "HNR-PVT")


def receiver_solutions(messages: dict) -> list[str]:
    """The receiver's own solution messages a u-blox log holds (what ``process`` falls back to without orbits)."""
    return [m for m in SOLUTION_MESSAGES if messages.get(m)]


def solutions_instead(path: str, kind: str, nav) -> list[str]:
    """The receiver's own solutions a pseudorange log without orbits is read through instead (a u-blox log without
    ``--nav`` holding NAV-PVT/NAV-SOL…: ``ubx-nav``); empty when there are none to fall back to."""
    return receiver_solutions(message_counts(path, kind)) if kind == "ubx" and nav is None else []


def track_extent(lat_deg: np.ndarray, lon_deg: np.ndarray) -> dict:
    """The box (lon/lat, degrees) of the finite positions."""
    ok = np.isfinite(lat_deg) & np.isfinite(lon_deg)
    if not ok.any():
        return {"box_deg": None}
    lat, lon = lat_deg[ok], lon_deg[ok]
    return {"box_deg": [round(float(lon.min()), 6), round(float(lat.min()), 6), round(float(lon.max()), 6), round(float(lat.max()), 6)]}


def _solution_info(path: str, kind: str) -> dict:
    """Epochs, span, rate, fix qualities and integrity evidence of a receiver's own solutions, streamed."""
    stats = ReadStats()
    epochs = with_position = 0
    first = last = None
    steps: Counter[float] = Counter()
    quality: Counter[int] = Counter()
    evidence = dict.fromkeys(("residuals", "receiver_raim", "error_ellipse", "satellites", "hdop"), 0)
    previous = None
    box = np.array([np.inf, np.inf, -np.inf, -np.inf])
    distance = DistanceCarry()
    for chunk in iter_navigation_tables(path, kind, stats=stats):
        e, s = chunk.epoch_columns, chunk.satellite_columns  # arrays: info imports no pandas
        lat, lon = e["lat_deg"].astype(float), e["lon_deg"].astype(float)
        ok = np.isfinite(lat) & np.isfinite(lon)
        t_s = np.where(np.isnat(e["time_utc"]), np.nan, e["time_utc"].astype("datetime64[ms]").astype(np.int64) / 1000.0)
        add_distance(distance, t_s, lat, lon, e["speed_mps"].astype(float) if "speed_mps" in e else None)
        if ok.any():
            box = np.array([min(box[0], lon[ok].min()), min(box[1], lat[ok].min()), max(box[2], lon[ok].max()), max(box[3], lat[ok].max())])
        epochs += len(e)
        with_position += int(ok.sum())
        t = e["time_utc"][~np.isnat(e["time_utc"])].astype(np.int64)  # ms since 1970, the dated epochs
        if t.size:
            first = int(t.min()) if first is None else min(first, int(t.min()))
            last = int(t.max()) if last is None else max(last, int(t.max()))
            times = t if previous is None else np.r_[previous, t]
            steps.update(np.round(np.diff(times) / 1000.0, 3).tolist())
            previous = times[-1]
        quality.update(e["fix_quality"].astype(int).tolist())
        sat_epoch = s["epoch"]
        evidence["residuals"] += np.unique(sat_epoch[np.isfinite(s["residual_m"].astype(float))]).size
        evidence["receiver_raim"] += int(np.isfinite(e["gbs_err_lat_m"].astype(float)).sum())
        evidence["error_ellipse"] += int((np.isfinite(e["sigma_major_m"].astype(float)) | np.isfinite(e["sigma_lat_m"].astype(float))).sum())
        evidence["satellites"] += np.unique(sat_epoch[s["used"].astype(bool)]).size
        evidence["hdop"] += int(np.isfinite(e["hdop"].astype(float)).sum())
    positive = {k: v for k, v in steps.items() if k > 0}
    rate_s = max(sorted(positive), key=positive.get) if positive else None
    level = next((name for name, key in LEVEL_EVIDENCE if evidence[key]), "model" if evidence["hdop"] else "none")
    return {
        "protocol": stats.protocol, "lines": stats.lines, "skipped_lines": stats.skipped,
        "first_problem": stats.first_problem or None, "epochs": epochs, "epochs_with_position": with_position,
        "first_utc": _iso_ms(first), "last_utc": _iso_ms(last),
        "span_s": round((last - first) / 1000.0, 3) if first is not None and last is not None else None,
        "interval_s": rate_s, "rate_hz": round(1.0 / rate_s, 3) if rate_s else None,
        "fix_quality": {str(k): v for k, v in sorted(quality.items()) if k >= 0},  # (-1: no GGA said: no quality to count)
        "box_deg": [round(float(v), 6) for v in box] if np.isfinite(box).all() else None, "distance_m": round(distance.distance_m, 1),
        "distance_from": distance_from(distance),
        "integrity_evidence_epochs": evidence, "integrity_level": level,
    }


def _iso_ms(ms: int | None) -> str | None:
    """Milliseconds since 1970 → ``YYYY-MM-DDTHH:MM:SS.mmmZ``."""
    return None if ms is None else str(np.datetime64(ms, "ms")) + "Z"


def _iso(stamp) -> str | None:
    return None if stamp is None else stamp.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
