"""OpenStreetMap roads (``.osm.pbf``, ``.osm``, ``.osm.bz2``) → columnar ways, nodes and tags, read with pyosmium.

pyosmium (the maintained binding of the C++ libosmium) parses the file and resolves node locations;
this module keeps the ways a vehicle can drive (``highway`` in :data:`DRIVABLE`) as flat arrays: per way
its id and the tags that matter for tolling (``highway``, ``ref``, ``name``, ``oneway``, ``layer``,
``bridge``, ``tunnel``, ``toll``, ``toll:hgv``, ``maxspeed``), and the concatenated node ids and
longitude/latitude of all ways with offsets (way k is ``offsets[k]:offsets[k + 1]``). Ways with a node
outside the extract (no location) lose that node; a way left with fewer than two nodes is dropped and
counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError

#: highway values of roads (not footways, cycleways, steps, platforms, construction)
DRIVABLE = frozenset({
    "motorway", "trunk", "primary", "secondary", "tertiary", "unclassified", "residential", "living_street", "service",
    "motorway_link", "trunk_link", "primary_link", "secondary_link", "tertiary_link", "road", "busway",
})  # fmt: skip
TAGS = ("highway", "ref", "name", "oneway", "layer", "bridge", "tunnel", "toll", "toll:hgv", "maxspeed")


@dataclass
class OsmRoads:
    ways: pd.DataFrame  # one row per way: way_id and the TAGS ('' where absent)
    offsets: np.ndarray  # (W + 1,) into the node arrays
    node_id: np.ndarray  # (N,) int64
    lon_deg: np.ndarray  # (N,)
    lat_deg: np.ndarray  # (N,)
    n_dropped: int  # ways with fewer than two located nodes


def read_osm_roads(path: str) -> OsmRoads:
    """The drivable ways of an OpenStreetMap file."""
    try:
        import osmium
    except ImportError:  # pragma: no cover - a dependency of the package
        raise UsageError("reading OpenStreetMap needs pyosmium (pip install osmium)") from None
    rows: list[tuple] = []
    counts: list[int] = []
    nodes: list[int] = []
    lons: list[float] = []
    lats: list[float] = []
    dropped = 0
    try:
        processor = osmium.FileProcessor(path).with_locations().with_filter(osmium.filter.KeyFilter("highway"))
        for way in processor:  # nodes are read for their locations; the filter passes tagged objects only
            if not way.is_way():
                continue
            tags = way.tags
            if tags.get("highway") not in DRIVABLE:
                continue
            located = [(n.ref, n.lon, n.lat) for n in way.nodes if n.location.valid()]
            if len(located) < 2:
                dropped += 1
                continue
            rows.append((way.id, *(tags.get(key, "") for key in TAGS)))
            counts.append(len(located))
            for ref, lon, lat in located:
                nodes.append(ref)
                lons.append(lon)
                lats.append(lat)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except RuntimeError as exc:  # libosmium: unreadable or damaged file
        raise DataError(f"{path}: not a readable OpenStreetMap file ({exc})") from None
    if not rows:
        raise DataError(f"{path}: no roads (no way with a drivable highway tag)")
    ways = pd.DataFrame(rows, columns=["way_id", *TAGS])
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return OsmRoads(ways, offsets, np.asarray(nodes, np.int64), np.asarray(lons, float), np.asarray(lats, float), dropped)


def is_osm(path: str) -> bool:
    """Whether a path names an OpenStreetMap file (by its extension, as libosmium decides the format)."""
    return str(path).lower().endswith((".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz", ".osc"))
