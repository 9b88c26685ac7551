"""The compiled store's spatial index and geometries: a uniform grid over bounding boxes, and polygons kept as WKB.

Both are plain arrays (numpy files of the store, memory-mapped: every worker of a batch shares the pages), so
loading costs nothing and a query touches only the cells the track passes and the geo-objects found there.

* :class:`GridIndex` — every geo-object's bounding box (in the file's search CRS, m) registered in the square cells
  it overlaps, stored as sorted cell keys with the members of each cell (compressed rows). A geo-object that would
  span more than ``MAX_CELLS`` cells (a section much longer than the network's typical one) is kept in a short
  list checked by its box against every query. :meth:`GridIndex.query` answers as shapely's ``STRtree.query`` does —
  the same pairs, sorted by (query, geo-object).
* :class:`StoredGeometries` — shapely geometries decoded from their WKB on first use and kept (WKB keeps every
  coordinate bit for bit). Indexing with an integer array gives an object array, as a numpy array of geometries does.
"""

from __future__ import annotations

import numpy as np
import shapely

from tollcli.errors import DataError

#: a geo-object whose box would cover more cells than this is checked by its box alone (the ``big`` list)
MAX_CELLS = 64


class StoredGeometries:
    """Geometries as one WKB byte array and the end offset of each (``ends``), decoded when first indexed."""

    def __init__(self, wkb: np.ndarray, ends: np.ndarray):
        self.wkb, self.ends = wkb, ends
        self._decoded = np.full(len(ends), None, dtype=object)

    def __len__(self) -> int:
        return len(self.ends)

    def __getitem__(self, index):
        if np.ndim(index) == 0:
            return self[np.array([index], dtype=np.int64)][0]
        index = np.asarray(index)
        if index.dtype == bool:
            index = np.flatnonzero(index)
        missing = np.unique(index[shapely.is_missing(self._decoded[index])]) if index.size else index
        if missing.size:
            starts = np.where(missing > 0, self.ends[np.maximum(missing - 1, 0)], 0)
            stops = self.ends[missing]
            try:
                self._decoded[missing] = shapely.from_wkb([self.wkb[a:b].tobytes() for a, b in zip(starts.tolist(), stops.tolist())])
            except shapely.errors.ShapelyError as exc:  # bytes changed on disk after the store was written
                where = getattr(self.wkb, "filename", None)
                raise DataError(f"{where or 'the geo-object store'}: damaged ({exc}); delete its folder and run "
                                "tollcli geoobjects compile") from None  # fmt: skip
        return self._decoded[index]

    def all(self) -> np.ndarray:
        """Every geometry (decodes them all: for whole-file work, not for recognition)."""
        return self[np.arange(len(self))]

    @classmethod
    def of(cls, geoms) -> "StoredGeometries":
        """Geometries kept as WKB (and the ones given kept decoded)."""
        geoms = np.asarray(geoms, dtype=object)
        wkb = shapely.to_wkb(geoms).tolist() if len(geoms) else []
        out = cls(np.frombuffer(b"".join(wkb), np.uint8), np.cumsum([len(w) for w in wkb], dtype=np.int64))
        out._decoded[:] = geoms
        return out


def grid_cell_m(bounds: np.ndarray) -> float:
    """The cell size for a network, m: the median extent of its boxes (a typical geo-object overlaps ≤ 4 cells)."""
    if not len(bounds):
        return 1000.0
    extent = np.maximum(bounds[:, 2] - bounds[:, 0], bounds[:, 3] - bounds[:, 1])
    return float(max(np.median(extent), 1.0))


def build_grid(bounds: np.ndarray, cell_m: float | None = None) -> dict[str, np.ndarray]:
    """The grid arrays for geo-objects of ``bounds`` (n × 4: minx, miny, maxx, maxy), in time linear in n."""
    n = len(bounds)
    cell = grid_cell_m(bounds) if cell_m is None else float(cell_m)
    origin = bounds[:, :2].min(axis=0) if n else np.zeros(2)
    lo = np.floor((bounds[:, :2] - origin) / cell).astype(np.int64)
    hi = np.floor((bounds[:, 2:] - origin) / cell).astype(np.int64)
    span = hi - lo + 1
    count = span[:, 0] * span[:, 1]
    big = count > MAX_CELLS
    small = np.flatnonzero(~big)
    rows = int(hi[:, 1].max(initial=0)) + 1
    k = count[small]
    obj = np.repeat(small, k)
    step = np.arange(obj.size) - np.repeat(np.cumsum(k) - k, k)  # 0 … k-1 within each geo-object
    width = span[obj, 1]
    keys = (lo[obj, 0] + step // width) * rows + lo[obj, 1] + step % width
    order = np.lexsort((obj, keys))
    keys, obj = keys[order], obj[order]
    first = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]) if keys.size else np.zeros(0, np.int64)
    return {"grid_keys": keys[first], "grid_first": np.r_[first, keys.size].astype(np.int64), "grid_members": obj.astype(np.int64),
            "grid_big": np.flatnonzero(big).astype(np.int64), "bounds": np.asarray(bounds, dtype=np.float64),
            "grid_spec": np.array([origin[0], origin[1], cell, rows], dtype=np.float64)}  # fmt: skip


class GridIndex:
    """Queries over the grid arrays of :func:`build_grid`; ``geometries``: the indexed geometries (search CRS)."""

    def __init__(self, arrays: dict[str, np.ndarray], geometries: StoredGeometries):
        self.keys, self.first, self.members = arrays["grid_keys"], arrays["grid_first"], arrays["grid_members"]
        self.big, self.bounds = arrays["grid_big"], arrays["bounds"]
        x0, y0, cell, rows = arrays["grid_spec"].tolist()
        self.origin, self.cell, self.rows = np.array([x0, y0]), cell, int(rows)
        self.geometries = geometries

    def __len__(self) -> int:
        return len(self.bounds)

    def boxes(self, qbounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(query, geo-object) for every pair of boxes that meet (edges included), sorted."""
        m = len(qbounds)
        if m == 0 or len(self.bounds) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        usable = np.isfinite(qbounds).all(axis=1)  # an empty geometry meets nothing
        cells = np.floor((np.where(usable[:, None], qbounds, 0.0) - np.tile(self.origin, 2)) / self.cell)
        cells = np.clip(cells, -(2.0**40), 2.0**40).astype(np.int64)  # a box far beyond the network: no overflow
        lo, hi = cells[:, :2], cells[:, 2:]
        lo[:, 1], hi[:, 1] = np.maximum(lo[:, 1], 0), np.minimum(hi[:, 1], self.rows - 1)  # rows outside hold nothing
        span = np.maximum(hi - lo + 1, 0)
        wide = usable & (span[:, 0].astype(float) * span[:, 1] > max(len(self.keys), 1))  # over more cells than there
        span[~usable | wide] = 0  # are: tested against every box
        k = span[:, 0] * span[:, 1]
        q = np.repeat(np.arange(m), k)
        step = np.arange(q.size) - np.repeat(np.cumsum(k) - k, k)
        width = span[q, 1]
        keys = (lo[q, 0] + step // np.maximum(width, 1)) * self.rows + lo[q, 1] + step % np.maximum(width, 1)
        at = np.searchsorted(self.keys, keys)
        found = at < len(self.keys)
        found[found] = self.keys[at[found]] == keys[found]
        q, at = q[found], at[found]
        n_in = self.first[at + 1] - self.first[at]
        qi = np.repeat(q, n_in)
        pos = np.repeat(self.first[at] - (np.cumsum(n_in) - n_in), n_in) + np.arange(qi.size)
        ti = self.members[pos]
        n = len(self.bounds)
        if self.big.size:
            every = np.flatnonzero(usable & ~wide)
            qi, ti = np.r_[qi, np.repeat(every, self.big.size)], np.r_[ti, np.tile(self.big, every.size)]
        if wide.any():
            every = np.flatnonzero(wide)
            qi, ti = np.r_[qi, np.repeat(every, n)], np.r_[ti, np.tile(np.arange(n), every.size)]
        b = self.bounds[ti]
        meet = (b[:, 0] <= qbounds[qi, 2]) & (b[:, 2] >= qbounds[qi, 0]) & (b[:, 1] <= qbounds[qi, 3]) & (b[:, 3] >= qbounds[qi, 1])
        pair = np.unique(qi[meet] * n + ti[meet])  # a geo-object in several of a box's cells: once
        return pair // n, pair % n

    def query(self, geometry, predicate: str | None = None, distance: float = 0.0):
        """As ``shapely.STRtree.query``: indices of the geo-objects whose boxes meet ``geometry``'s (one geometry) or
        (input, geo-object) index pairs (an array); with ``predicate`` (``intersects``, ``dwithin`` with
        ``distance``, or any shapely binary predicate) the pairs for which it holds."""
        single = np.ndim(geometry) == 0
        geoms = np.atleast_1d(np.asarray(geometry, dtype=object))
        qbounds = shapely.bounds(geoms)
        if predicate == "dwithin":
            qbounds = qbounds + np.array([-distance, -distance, distance, distance])
        qi, ti = self.boxes(qbounds)
        if predicate is not None and qi.size:
            if predicate == "dwithin":
                holds = shapely.dwithin(geoms[qi], self.geometries[ti], distance)
            else:
                holds = getattr(shapely, predicate)(geoms[qi], self.geometries[ti])
            qi, ti = qi[holds], ti[holds]
        return ti if single else np.vstack([qi, ti])
