"""The shortest stretch of road a geo-object is worth building on: long enough for the recognition to see it.

A passage is charged on ``N_th`` valid positions at least ``T_c`` apart (thesis §3.4). A vehicle driving a section at
its speed through a core of length L gives a receiver logging once a second ``L / v`` seconds of positions; to give
``N_th`` of them ``T_c`` apart it needs ``L ≥ v · ((N_th − 1) · T_c + 1 s)``. A shorter geo-object (a 1 m core at
HAL 5 m left by the junction trims of a section of 327 m) is missed at speed — or, caught by a single position, charges
the whole section from it: it is skipped, with why.

The section's speed is its ``maxspeed`` (km/h, OpenStreetMap's tag, a number) where it has one, else its road
class's typical limit (:data:`CLASS_SPEED_KMH`), else :data:`OTHER_SPEED_KMH`.
"""

from __future__ import annotations

import re

#: a road class's speed when the road gives none, km/h (European motorway and rural limits)
CLASS_SPEED_KMH = {"motorway": 130.0, "motorway_link": 80.0, "trunk": 110.0, "trunk_link": 80.0, "primary": 90.0,
                   "secondary": 80.0, "tertiary": 70.0}  # fmt: skip
#: any other road's speed, km/h (a town street)
OTHER_SPEED_KMH = 50.0
#: the receiver's epoch interval the length is counted for, s (1 Hz: the slowest the recognition is designed for)
EPOCH_S = 1.0


def section_speed_mps(props: dict) -> float:
    """A section's speed, m/s: its numeric ``maxspeed`` (km/h) if any, else its road class's."""
    text = str(props.get("maxspeed") or "")
    match = re.fullmatch(r"\s*(\d{1,3}(?:\.\d+)?)\s*(km/h|kmh|kph)?\s*", text)
    kmh = float(match.group(1)) if match and 5.0 <= float(match.group(1)) <= 200.0 else None
    if kmh is None:
        kmh = CLASS_SPEED_KMH.get(str(props.get("road_class") or ""), OTHER_SPEED_KMH)
    return kmh / 3.6


def min_core_m(props: dict, n_th: int = 1, tc_s: float = 5.0) -> float:
    """The shortest core (centre line kept) a section's geo-object may have, m: ``v · ((N_th − 1) · T_c + 1 s)``."""
    return round(section_speed_mps(props) * ((max(int(n_th), 1) - 1) * float(tc_s) + EPOCH_S), 1)
