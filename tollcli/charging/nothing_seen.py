"""Where a log's track was when it came near no geo-object: an invoice that charged nothing and saw nothing says how far
the track stayed from the network, so that a wrong network or a wrong CRS is not taken for a clean day.

A chunk at a time the track's box is widened and a thinned sample of its positions kept (at most
``SAMPLE_MAX`` positions, whatever the log's length); at the end the distance from each sampled position to every
geo-object's box (its corners taken to longitude/latitude; great-circle metres to the box's nearest point) gives the
nearest geo-object. A box is never further than the geo-object it holds: the distance is about a lower bound, said as
"no closer than".
"""

from __future__ import annotations

import numpy as np

from tollcli.geodesy import great_circle_distance_m
from tollcli.spatial import wgs84_to

#: the most positions kept to measure the distance (a 10 h log at 1 Hz: one every 36 s or so)
SAMPLE_MAX = 1_000
#: the most geo-object boxes measured against at once (memory: SAMPLE_MAX × this doubles)
BOX_BLOCK = 20_000


class TrackExtent:
    """A log's track box (lon/lat, degrees) and a thinned sample of its positions, filled chunk by chunk."""

    def __init__(self) -> None:
        self.box = np.array([np.inf, np.inf, -np.inf, -np.inf])
        self.lon: np.ndarray = np.zeros(0)
        self.lat: np.ndarray = np.zeros(0)
        self.step = 1
        self.seen = 0

    def add(self, lon_deg: np.ndarray, lat_deg: np.ndarray) -> None:
        """Widen the box by the finite positions of a chunk and keep every ``step``-th (the step doubles when full)."""
        lon, lat = np.asarray(lon_deg, float), np.asarray(lat_deg, float)
        ok = np.isfinite(lon) & np.isfinite(lat) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
        lon, lat = lon[ok], lat[ok]
        if not lon.size:
            return
        self.box = np.array([min(self.box[0], lon.min()), min(self.box[1], lat.min()), max(self.box[2], lon.max()),
                             max(self.box[3], lat.max())])  # fmt: skip
        take = (self.seen + np.arange(lon.size)) % self.step == 0
        self.seen += lon.size
        self.lon, self.lat = np.concatenate([self.lon, lon[take]]), np.concatenate([self.lat, lat[take]])
        while self.lon.size > SAMPLE_MAX:
            self.lon, self.lat, self.step = self.lon[::2], self.lat[::2], self.step * 2

    def report(self, geo) -> dict | None:
        """What the invoice says: the track's box, the network's, whether they overlap, the nearest geo-object and how
        close the track came to its box (m, a lower bound); None when the log had no position."""
        if not self.lon.size:
            return None
        bounds = np.asarray(geo.index.bounds, float)
        out = {"track_box_deg": [round(float(v), 6) for v in self.box]}
        if not len(bounds):
            return {**out, "network_box_deg": None, "boxes_overlap": False, "nearest_geoobject": None, "nearest_distance_m": None}
        to_deg = wgs84_to(geo.crs).transform
        lons, lats = [], []
        for cx, cy in ((0, 1), (2, 3), (0, 3), (2, 1)):  # each box's corners in lon/lat: the boxes there
            lon, lat = to_deg(bounds[:, cx], bounds[:, cy], direction="INVERSE")
            lons.append(np.asarray(lon, float))
            lats.append(np.asarray(lat, float))
        boxes = np.column_stack([np.min(lons, 0), np.min(lats, 0), np.max(lons, 0), np.max(lats, 0)])
        network = [float(np.nanmin(boxes[:, 0])), float(np.nanmin(boxes[:, 1])), float(np.nanmax(boxes[:, 2])),
                   float(np.nanmax(boxes[:, 3]))]  # fmt: skip
        overlap = not (self.box[2] < network[0] or self.box[0] > network[2] or self.box[3] < network[1] or self.box[1] > network[3])
        best_d, best_k = np.inf, -1
        for start in range(0, len(boxes), BOX_BLOCK):
            b = boxes[start : start + BOX_BLOCK]
            # each position clamped into each box: the box's nearest point (in lon/lat), then the great-circle distance
            lon = np.clip(self.lon[:, None], b[None, :, 0], b[None, :, 2])
            lat = np.clip(self.lat[:, None], b[None, :, 1], b[None, :, 3])
            d = great_circle_distance_m(self.lat[:, None], self.lon[:, None], lat, lon)
            flat = int(np.nanargmin(d)) if np.isfinite(d).any() else -1
            if flat >= 0 and d.flat[flat] < best_d:
                best_d, best_k = float(d.flat[flat]), start + flat % len(b)
        return {**out, "network_box_deg": [round(v, 6) for v in network], "boxes_overlap": bool(overlap),
                "nearest_geoobject": str(geo.ids[best_k]) if best_k >= 0 else None,
                "nearest_distance_m": round(best_d, 1) if best_k >= 0 else None}  # fmt: skip


def nothing_seen_words(report: dict) -> str:
    """One sentence for the summary line: how far the track stayed from the network."""
    if report.get("nearest_distance_m") is None:
        return "no geo-object to come near"
    km = report["nearest_distance_m"] / 1000.0
    where = "inside the network's box" if report["boxes_overlap"] else "outside the network's box (a wrong network or CRS?)"
    return f"the track came no closer than {km:,.1f} km to a geo-object ({report['nearest_geoobject']}), {where}"
