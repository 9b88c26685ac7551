"""Tunnel outages: GNSS does not reach a tunnel, so the gap or fix loss at one is expected, not an attack.

Geo-objects carry the metres of them in tunnels (``tunnel_m``, from OpenStreetMap's ``tunnel`` ways);
``recognition`` keeps the fixes before and after a tunnel in one passage, and the findings that such an
outage would otherwise raise (a gap, a fix lost at speed, satellites or C/N0 collapsing) become
``tunnel_outage`` (category ``expected``), keeping the kind they replace under ``evidence.explains``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import shapely

#: the kinds a tunnel explains (GNSS lost, satellites and C/N0 gone with it)
OUTAGE_KINDS = ("gap", "fix_lost_at_speed", "satellite_collapse", "cn0_collapse")


def tunnel_outages(found: list[dict], geo, portal_m: float = 50.0, reacquire_s: float = 60.0) -> list[dict]:
    """Findings an outage in a tunnel explains, replaced by ``tunnel_outage`` (the rest unchanged).

    A finding of :data:`OUTAGE_KINDS` is explained when its start or end lies within ``portal_m`` of a
    geo-object with a tunnel and it lasts at most that tunnel's time (``geo.tunnel_times_s()``) + ``reacquire_s``;
    one without a position (satellites collapsing while there is no fix) when it lies within the time of an
    outage so explained.
    """
    times = geo.tunnel_times_s() if geo is not None and hasattr(geo, "tunnel_times_s") else None
    if times is None or not (times > 0).any():
        return found
    from tollcli.spatial import wgs84_to

    tr = wgs84_to(geo.crs)
    out = []
    for f in found:
        ends = [(f["lon_deg"], f["lat_deg"]), (f["end_lon_deg"], f["end_lat_deg"])]
        ends = [(lon, lat) for lon, lat in ends if lon is not None and lat is not None]
        if f["kind"] not in OUTAGE_KINDS or not ends:
            out.append(f)
            continue
        x, y = tr.transform([e[0] for e in ends], [e[1] for e in ends])
        _, near = geo.index.query(shapely.points(x, y), predicate="dwithin", distance=portal_m)
        near = np.unique(near[times[near] > 0])
        duration_s = (pd.Timestamp(f["end_utc"]) - pd.Timestamp(f["start_utc"])).total_seconds()
        if near.size and duration_s <= times[near].max() + reacquire_s:
            f = {**f, "kind": "tunnel_outage", "category": "expected",
                 "evidence": {**f["evidence"], "explains": f["kind"], "tunnel_geoobjects": sorted(str(geo.ids[i]) for i in near),
                              "tunnel_m": round(float(geo.tunnel_lengths_m()[near].max()), 1)}}  # fmt: skip
        out.append(f)
    return _within_explained(out)


def _within_explained(found: list[dict]) -> list[dict]:
    """Outage findings without a position that lie inside the time of a tunnel outage: explained by it too."""
    spans = [(f["start_utc"], f["end_utc"], f) for f in found if f["kind"] == "tunnel_outage"]
    out = []
    for f in found:
        if f["kind"] in OUTAGE_KINDS and f["lat_deg"] is None and f["end_lat_deg"] is None:
            host = next((h for a, b, h in spans if a <= f["start_utc"] and f["end_utc"] <= b), None)
            if host is not None:
                f = {**f, "kind": "tunnel_outage", "category": "expected",
                     "evidence": {**f["evidence"], "explains": f["kind"], "tunnel_geoobjects": host["evidence"]["tunnel_geoobjects"],
                                  "tunnel_m": host["evidence"]["tunnel_m"]}}  # fmt: skip
        out.append(f)
    return out
