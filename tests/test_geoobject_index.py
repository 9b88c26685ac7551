"""The compiled store's grid index answers as shapely's STRtree does, and its geometries come back bit for bit."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tollcli.geoobjects.index import MAX_CELLS, GridIndex, StoredGeometries, build_grid


def _index(geoms):
    stored = StoredGeometries.of(geoms)
    fresh = StoredGeometries(stored.wkb, stored.ends)  # as mapped from a store: nothing decoded yet
    return GridIndex(build_grid(shapely.bounds(geoms)), fresh)


def _pairs(result) -> set:
    return set(map(tuple, np.asarray(result).T.tolist()))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 120), long_share=st.floats(0, 0.3))
def test_grid_finds_what_the_strtree_finds(seed, n, long_share):
    """Random buffered segments (some far longer than the rest: the boxes checked alone), points, lines and
    discs: the grid's pairs are STRtree.query's, with and without a predicate."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(0, 5000, (n, 2))
    length = np.where(rng.random(n) < long_share, rng.uniform(2000, 20000, n), rng.uniform(50, 400, n))
    angle = rng.uniform(0, 2 * np.pi, n)
    end = start + np.column_stack([np.cos(angle), np.sin(angle)]) * length[:, None]
    geoms = shapely.buffer(shapely.linestrings(np.stack([start, end], axis=1)), rng.uniform(5, 50, n))
    tree, grid = shapely.STRtree(geoms), _index(geoms)
    points = shapely.points(rng.uniform(-500, 8000, (300, 2)))
    points = np.r_[points, shapely.points(shapely.bounds(geoms)[:, :2])]  # on the boxes' corners: edges count
    assert _pairs(grid.query(points)) == _pairs(tree.query(points))
    assert _pairs(grid.query(points, predicate="dwithin", distance=30.0)) == _pairs(tree.query(points, predicate="dwithin", distance=30.0))
    line = shapely.LineString(rng.uniform(-500, 8000, (2, 2)))
    assert set(grid.query(line, predicate="intersects").tolist()) == set(tree.query(line, predicate="intersects").tolist())
    everything = shapely.box(-1e6, -1e6, 1e6, 1e6)  # a box over more cells than there are
    assert set(grid.query(everything).tolist()) == set(range(n))
    assert grid.query(shapely.Point()).size == 0  # an empty geometry meets nothing


def test_long_geoobjects_are_checked_by_their_box():
    short = shapely.buffer(shapely.linestrings([[[0, 0], [100, 0]]] * 9 + [[[0, 50], [100, 50]]]), 10)
    long = shapely.buffer(shapely.LineString([[0, 0], [100 * 40, 100 * 40]]), 10)
    grid = _index(np.r_[short, long])
    assert grid.big.tolist() == [10]  # over more than MAX_CELLS cells
    assert MAX_CELLS < 40 * 40
    assert grid.query(shapely.Point(2000, 2000)).tolist() == [10]


def test_stored_geometries_decode_bit_for_bit_and_once():
    geoms = shapely.buffer(shapely.points(np.random.default_rng(1).uniform(0, 1e6, (50, 2))), 12.345678901234)
    stored = StoredGeometries.of(geoms)
    fresh = StoredGeometries(stored.wkb, stored.ends)
    picked = fresh[np.array([7, 3, 7, 49, 0])]
    assert (shapely.to_wkb(picked) == shapely.to_wkb(geoms[[7, 3, 7, 49, 0]])).all()
    assert picked[0] is picked[2] is fresh[7]  # decoded once, kept
    assert shapely.is_missing(fresh._decoded).sum() == 50 - 4
    assert (shapely.to_wkb(fresh.all()) == shapely.to_wkb(geoms)).all()
