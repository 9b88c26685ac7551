"""What a geo-object file holds (``tollcli geoobjects info``): counts, HAL histogram, the share of the tolled length
its geo-objects cover, and for each geo-object the road that bounds its HAL and how far away that road is."""

from __future__ import annotations

import numpy as np

from tollcli.geoobjects.city import kind_of


#: HAL histogram bin edges, m (the papers' 25–50 m range in the middle)
HAL_BINS_M = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, float("inf"))


def _number(value, default=float("nan")) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return default


def covered_lengths_m(props: list[dict], skipped: list[dict], min_hal_m: float = 0.0) -> tuple[float, float, float]:
    """(tolled length, length covered, length covered by geo-objects of HAL ≥ ``min_hal_m``), m, from geo-objects'
    properties (``section_length_m``, else ``length_m``) and the sections a build skipped."""
    hal = np.array([_number(p.get("hal_m")) for p in props])
    length = np.nan_to_num(np.array([_number(p.get("length_m")) for p in props]))
    section = np.nan_to_num(np.array([_number(p.get("section_length_m", p.get("length_m"))) for p in props]))
    tolled = float(section.sum() + sum(_number(s.get("section_length_m"), 0.0) for s in skipped))
    return tolled, float(length.sum()), float(length[hal >= min_hal_m].sum())


def geoobject_info(path: str, min_hal_m: float = 25.0) -> dict:
    """The summary of a geo-object file as a JSON-ready dict (lengths in metres)."""
    from tollcli.geoobjects.geojson_stream import gc_paused, stream_collection

    with gc_paused():  # feature by feature, the properties only: a national network's file is never held whole
        doc, _ = stream_collection(path, geometry=False)
    doc_features = doc["features"]
    build = doc.get("tollcli") if isinstance(doc.get("tollcli"), dict) else {}
    skipped = build.get("skipped") or []
    props = [f.get("properties") or {} for f in doc_features]
    rows = []
    for p in props:
        parts = p.get("parts")
        rows.append({
            "id": str(p.get("id")), "kind": kind_of(p), "road_class": p.get("road_class", ""), "hal_m": _number(p.get("hal_m")),
            "design_hal_m": p.get("design_hal_m"), "length_m": _number(p.get("length_m")),
            "section_length_m": _number(p.get("section_length_m", p.get("length_m"))),
            "parts": len(parts) if isinstance(parts, list) else 1, "hal_bound": p.get("hal_bound"),
            "nearest_road": p.get("nearest_road"), "nearest_road_m": p.get("nearest_road_m"), "cut_around": p.get("crossings", []),
        })  # fmt: skip
    hal = np.array([r["hal_m"] for r in rows])
    tolled_m, covered_m, at_min_m = covered_lengths_m(props, skipped, min_hal_m)
    counts, _ = np.histogram(hal[np.isfinite(hal)], bins=HAL_BINS_M)
    below = [r["id"] for r in rows if isinstance(r["design_hal_m"], list) and r["hal_m"] < float(r["design_hal_m"][0])]
    return {
        "file": path, "geoobjects": len(rows), "sections_skipped": len(skipped),
        "kinds": {k: sum(r["kind"] == k for r in rows) for k in sorted({r["kind"] for r in rows})},
        "hal_m": {"min": float(np.nanmin(hal)) if len(hal) else None, "median": float(np.nanmedian(hal)) if len(hal) else None,
                  "max": float(np.nanmax(hal)) if len(hal) else None},
        "hal_histogram": [{"from_m": lo, "to_m": (hi if np.isfinite(hi) else None), "count": int(n)}
                          for lo, hi, n in zip(HAL_BINS_M[:-1], HAL_BINS_M[1:], counts)],
        "tolled_length_m": round(tolled_m, 1), "covered_length_m": round(covered_m, 1),
        "covered_share": round(covered_m / tolled_m, 4) if tolled_m > 0 else None,
        "min_hal_m": min_hal_m, "covered_at_min_hal_m": round(at_min_m, 1),
        "covered_share_at_min_hal": round(at_min_m / tolled_m, 4) if tolled_m > 0 else None,
        "below_design_hal": below, "skipped": skipped, "features": rows,
    }  # fmt: skip
