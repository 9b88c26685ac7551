"""An OpenStreetMap road network → tolled sections between junctions and free roads, with their topology.

Real tolls charge sections: the stretch of a tolled road between two junctions. OpenStreetMap splits
roads into ways wherever a tag changes (a bridge, a speed limit), so ways are first cut at every
junction node — a node where the road graph branches or ends (more or fewer than two way ends or
interior passages meet), or where tolled and free ways meet — and the tolled pieces are then chained
through the remaining nodes into sections. A section keeps its OSM way ids, ``ref``, name, road class
(``highway``), length, travel direction (``oneway``) and whether part of it runs in a tunnel.

Roads meet only where they share a node: a road crossing on a bridge or in a tunnel, or merely drawn
across another without a common node, is not connected to it (grade separation), whatever the 2-D
geometry says. :func:`osm_roads` gives the sections and the free ways (whole) as
:class:`tollcli.geoobjects.build.Roads` with those junctions.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import shapely
from pyproj import Geod

from tollcli.geoobjects.build import Roads
from tollcli.errors import UsageError
from tollcli.geoobjects.osm import OsmRoads

#: ground lengths (tunnel_m) on the WGS-84 ellipsoid
_GEOD = Geod(ellps="WGS84")


def tolled_ways(ways: pd.DataFrame, rules: list[str]) -> np.ndarray:
    """Which ways are tolled: any rule matches. A rule is ``key=value[,value…]`` (a tag with one of the values, ``*``
    for any), ``way:ID[,ID…]`` (OSM way ids) or ``ref:REF[,REF…]`` (road references)."""
    if not rules:
        raise UsageError("give the tolled roads: --tolled 'highway=primary' (or toll=yes, way:ID,…, ref:E18,…)")
    chosen = np.zeros(len(ways), bool)
    for rule in rules:
        kind, sep, values = rule.partition("=") if "=" in rule else rule.partition(":")
        listed = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not kind.strip() or not listed:
            raise UsageError(f"--tolled {rule!r}: expected key=value[,value…], way:ID[,ID…] or ref:REF[,REF…]")
        kind = kind.strip()
        if sep == ":" and kind == "way":
            try:
                chosen |= ways["way_id"].isin([int(v) for v in listed]).to_numpy()
            except ValueError:
                raise UsageError(f"--tolled {rule!r}: way ids are integers") from None
        elif sep == ":" and kind == "ref":
            refs = ways["ref"].str.split(";").map(lambda r: {x.strip() for x in r})
            chosen |= refs.map(lambda r: bool(r & set(listed))).to_numpy(bool)
        elif sep == "=":
            if kind not in ways:
                raise UsageError(f"--tolled {rule!r}: tag {kind!r} is not read (known: {', '.join(c for c in ways if c != 'way_id')})")
            column = ways[kind]
            chosen |= (column != "").to_numpy() if listed == ["*"] else column.isin(listed).to_numpy()
        else:
            raise UsageError(f"--tolled {rule!r}: expected key=value[,value…], way:ID[,ID…] or ref:REF[,REF…]")
    return chosen


def _pieces(osm: OsmRoads, tolled: np.ndarray) -> tuple[pd.DataFrame, set[int]]:
    """Every way cut at its junction nodes: one row per piece (way index, first and last node position), and the
    junction node ids."""
    n_ways = len(osm.offsets) - 1
    way_of = np.repeat(np.arange(n_ways), np.diff(osm.offsets))
    first = np.zeros(len(osm.node_id), bool)
    first[osm.offsets[:-1]] = True
    last = np.zeros(len(osm.node_id), bool)
    last[osm.offsets[1:] - 1] = True
    # passages through a node: an interior node is passed twice (in and out), an end once
    passes = np.where(first | last, 1, 2)
    degree = pd.Series(passes).groupby(osm.node_id).sum()
    kinds = pd.Series(tolled[way_of]).groupby(osm.node_id).nunique()
    junction_nodes = set(degree.index[(degree.to_numpy() != 2) | (kinds.reindex(degree.index).to_numpy() > 1)].tolist())
    cut = np.isin(osm.node_id, list(junction_nodes)) | first | last
    rows = []
    for k in range(n_ways):  # a cut per junction node; the loop is over ways (thousands), not positions
        at = np.flatnonzero(cut[osm.offsets[k] : osm.offsets[k + 1]]) + osm.offsets[k]
        rows += [(k, a, b) for a, b in zip(at[:-1].tolist(), at[1:].tolist())]
    return pd.DataFrame(rows, columns=["way", "start", "end"]), junction_nodes


def _chains(pieces: pd.DataFrame, node_id: np.ndarray, junctions: set[int]) -> list[list[tuple[int, bool]]]:
    """Tolled pieces chained through their shared non-junction end nodes: per section, (piece, reversed) in order."""
    ends: dict[int, list[int]] = {}
    for p, (a, b) in enumerate(zip(pieces["start"].tolist(), pieces["end"].tolist())):
        for node in (int(node_id[a]), int(node_id[b])):
            ends.setdefault(node, []).append(p)
    unused = set(range(len(pieces)))
    start_node = {p: int(node_id[a]) for p, a in enumerate(pieces["start"].tolist())}
    end_node = {p: int(node_id[b]) for p, b in enumerate(pieces["end"].tolist())}
    chains = []
    for seed in range(len(pieces)):
        if seed not in unused:
            continue
        unused.discard(seed)
        chain = [(seed, False)]
        for forward in (True, False):  # grow past the seed's end node, then past its start node
            node = end_node[seed] if forward else start_node[seed]
            while True:
                nxt = [q for q in ends.get(node, []) if q in unused]
                if node in junctions or len(ends.get(node, [])) != 2 or not nxt:
                    break
                q = nxt[0]
                unused.discard(q)
                rev = end_node[q] == node if forward else start_node[q] == node
                if forward:
                    chain.append((q, rev))
                    node = start_node[q] if rev else end_node[q]
                else:
                    chain.insert(0, (q, rev))
                    node = end_node[q] if rev else start_node[q]
        chains.append(chain)
    return chains


def osm_roads(osm: OsmRoads, rules: list[str]) -> Roads:
    """Tolled sections (chained pieces) and free ways as roads with their junctions (shared nodes)."""
    ways = osm.ways
    tolled = tolled_ways(ways, rules)
    if not tolled.any():
        raise UsageError(f"--tolled {' '.join(rules)}: no way of the map matches")
    pieces, junctions = _pieces(osm, tolled)
    tolled_pieces = pieces[tolled[pieces["way"].to_numpy()]].reset_index(drop=True)
    ids, props, lines, node_sets = [], [], [], []
    xy = np.column_stack([osm.lon_deg, osm.lat_deg])
    for chain in _chains(tolled_pieces, osm.node_id, junctions):
        idx = []
        for p, rev in chain:
            a, b = int(tolled_pieces.at[p, "start"]), int(tolled_pieces.at[p, "end"])
            seg = list(range(a, b + 1))
            idx += (seg[::-1] if rev else seg)[(1 if idx else 0) :]
        way_rows = [int(tolled_pieces.at[p, "way"]) for p, _ in chain]
        line = shapely.LineString(xy[idx])
        w = ways.iloc[way_rows]
        reversed_oneway = [(tag == "yes" and rev) or (tag == "-1" and not rev) for tag, (_, rev) in zip(w["oneway"], chain)]
        oneway = bool((w["oneway"].isin(["yes", "-1", "true", "1"])).all())
        if oneway and all(reversed_oneway):
            line = shapely.LineString(xy[idx[::-1]])
            idx = idx[::-1]
        tunnel_pieces = [p for (p, _), t in zip(chain, w["tunnel"]) if t not in ("", "no")]
        tunnel_m = sum(_GEOD.line_length(*xy[int(tolled_pieces.at[p, "start"]) : int(tolled_pieces.at[p, "end"]) + 1].T)
                       for p in tunnel_pieces)  # fmt: skip
        first_way = int(w["way_id"].iloc[0])
        ids.append(f"osm{first_way}:{int(osm.node_id[idx[0]])}-{int(osm.node_id[idx[-1]])}")
        props.append({
            "tolled": True, "name": _first(w["name"]), "ref": _first(w["ref"]), "road_class": _first(w["highway"]),
            "osm_way_ids": sorted(set(w["way_id"].astype(int).tolist())), "oneway": oneway and not (any(reversed_oneway) and not all(reversed_oneway)),
            "tunnel": bool(tunnel_pieces), "tunnel_m": round(tunnel_m, 1), "maxspeed": _first(w["maxspeed"]),
        })  # fmt: skip
        lines.append(line)
        node_sets.append(osm.node_id[idx])
    free = np.flatnonzero(~tolled)
    for k in free.tolist():
        a, b = int(osm.offsets[k]), int(osm.offsets[k + 1])
        row = ways.iloc[k]
        ids.append(f"osm{int(row['way_id'])}")
        props.append({"tolled": False, "name": row["name"], "road_class": row["highway"], "layer": row["layer"],
                      "bridge": row["bridge"], "tunnel": row["tunnel"]})  # fmt: skip
        lines.append(shapely.LineString(xy[a:b]))
        node_sets.append(osm.node_id[a:b])
    return Roads(ids, props, lines, _shared_nodes(node_sets))


def _first(values: pd.Series) -> str:
    present = [v for v in values if v]
    return present[0] if present else ""


def _shared_nodes(node_sets: list[np.ndarray]) -> set[tuple[int, int]]:
    """Pairs of roads (indices) with a node in common."""
    road = np.repeat(np.arange(len(node_sets)), [len(n) for n in node_sets])
    table = pd.DataFrame({"node": np.concatenate(node_sets), "road": road}).drop_duplicates()
    pairs = table.merge(table, on="node")
    pairs = pairs[pairs["road_x"] < pairs["road_y"]]
    return set(zip(pairs["road_x"].tolist(), pairs["road_y"].tolist()))
