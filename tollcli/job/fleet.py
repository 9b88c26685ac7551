"""A fleet file: each vehicle's class and tariff attributes, so one ``batch`` charges a mixed fleet.

CSV (UTF-8, a header row), one row per vehicle id (as ``batch`` names vehicles: the log's
``# vehicle:`` header, else its file name)::

    vehicle,vehicle_class,weight_class,axles,euro_class,co2_class
    TRK-042,truck,over-18t,5+,euro6,1
    TRK-043,truck,12-18t,3,euro5,2
    BUS-7,bus,over-18t,3,euro6,

``vehicle`` and ``vehicle_class`` are required; every other column is a vehicle attribute of a per-km
tariff (``--vehicle-attr``), an empty cell meaning the vehicle does not have it. A vehicle listed twice, a
row without an id or class, or a column that is not a plain name is an error naming the file and line.
"""

from __future__ import annotations

import csv
import re

from tollcli.errors import DataError, UsageError

REQUIRED = ("vehicle", "vehicle_class")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def read_fleet(path: str) -> dict[str, tuple[str, dict[str, str] | None]]:
    """vehicle id → (vehicle class, attributes or None)."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a fleet CSV") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"{path}: not a readable CSV ({exc})") from None
    if not rows:
        raise DataError(f"{path}: empty (expected a header: vehicle,vehicle_class,…)")
    header = [h.strip() for h in rows[0]]
    for name in REQUIRED:
        if name not in header:
            raise DataError(f"{path}:1: no {name!r} column (the header has {', '.join(header) or 'nothing'})")
    for name in header:
        if not _NAME.match(name):
            raise DataError(f"{path}:1: column {name!r} is not a plain name (attributes are like euro_class)")
    if len(set(header)) != len(header):
        raise DataError(f"{path}:1: a column is named twice")
    out: dict[str, tuple[str, dict[str, str] | None]] = {}
    for number, row in enumerate(rows[1:], 2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise DataError(f"{path}:{number}: {len(row)} cells, the header has {len(header)}")
        cells = dict(zip(header, (cell.strip() for cell in row)))
        vehicle, vehicle_class = cells.pop("vehicle"), cells.pop("vehicle_class")
        if not vehicle or not vehicle_class:
            raise DataError(f"{path}:{number}: a vehicle needs its id and its vehicle_class")
        if vehicle in out:
            raise DataError(f"{path}:{number}: vehicle {vehicle!r} is listed twice")
        attrs = {k: v for k, v in sorted(cells.items()) if v}
        out[vehicle] = (vehicle_class, attrs or None)
    return out
