"""Road networks from vector files: GeoJSON, GeoPackage, Shapefile, FlatGeobuf (anything GDAL reads, via pyogrio).

Every format gives the same thing: GeoJSON-like features (``{"type", "properties", "geometry"}``) in WGS-84
longitude/latitude. GeoJSON is read as written (RFC 7946: WGS-84, and a ``crs`` member naming anything else is
refused); other files are reprojected from the CRS they declare (a Shapefile's ``.prj``), and a file that declares
none is refused rather than guessed. Reprojected coordinates are rounded to 1e-9° (0.1 mm), so that a network
written in another CRS and read back gives the very coordinates — and geo-objects — of the original. Absent
values (a GeoPackage's NULL, a Shapefile's empty field) are dropped from the properties, and numbers and booleans
come back as plain Python values.
"""

from __future__ import annotations

import warnings

from pathlib import Path

import numpy as np
import shapely

from tollcli.errors import DataError, UsageError
from tollcli.spatial import read_features

#: file name endings read through GDAL (GeoJSON is read directly)
VECTOR_SUFFIXES = (".gpkg", ".shp", ".fgb", ".shp.zip", ".gdb")
#: decimal places of degrees kept from a reprojection (1e-9° ≈ 0.1 mm)
ROUND_DEG_DECIMALS = 9


def is_vector_file(path: str) -> bool:
    return str(path).lower().endswith(VECTOR_SUFFIXES)


def read_road_features(path: str) -> list[dict]:
    """The features of a road file in WGS-84 (GeoJSON as is; other vector formats through pyogrio)."""
    if not is_vector_file(path):
        return read_features(path)
    if not Path(path).exists():
        raise UsageError(f"{path}: no such file")
    import pyogrio

    try:
        with warnings.catch_warnings():  # GDAL's notes on a field it read partly (a damaged .dbf) are no messages of ours
            warnings.simplefilter("ignore", RuntimeWarning)
            frame = pyogrio.read_dataframe(path)
    except Exception as exc:  # pyogrio raises its own and GDAL's errors: any of them means the file is unreadable
        raise DataError(f"{path}: not a readable vector file ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    if frame.crs is None:
        raise DataError(f"{path}: declares no coordinate reference system (a Shapefile needs its .prj)")
    try:
        reproject = not frame.crs.equals("EPSG:4326") and not frame.crs.equals("OGC:CRS84")
        geometry = frame.geometry.to_crs("EPSG:4326") if reproject else frame.geometry
    except Exception as exc:  # PROJ's errors (a CRS on Mars, a projection without its conversion): the file's CRS is unusable
        first = " ".join(str(exc).split())[:200]
        raise DataError(f"{path}: its coordinate reference system cannot be turned into WGS-84 ({type(exc).__name__}: {first})") from None
    geoms = np.asarray(geometry.array, dtype=object)
    if reproject:
        geoms = shapely.transform(geoms, _round_degrees)
    columns, seen = [], set()
    for j, c in enumerate(frame.columns):  # by position: a damaged .dbf can name two columns alike (the first one counts)
        if c != frame.geometry.name and str(c) not in seen:
            seen.add(str(c))
            columns.append((j, str(c)))
    features = []
    for k, geom in enumerate(geoms.tolist()):
        props = {c: _plain(frame.iat[k, j]) for j, c in columns}
        features.append({"type": "Feature", "properties": {c: v for c, v in props.items() if v is not None},
                         "geometry": shapely.geometry.mapping(geom) if geom is not None else None})  # fmt: skip
    return features


def _round_degrees(xy: np.ndarray) -> np.ndarray:
    """Degrees rounded to ROUND_DEG_DECIMALS places, correctly (the double nearest the decimal, as a parser gives)."""
    return np.array([[float(f"{v:.{ROUND_DEG_DECIMALS}f}") for v in row] for row in xy.tolist()]).reshape(xy.shape)


def _plain(value):
    """A dataframe cell as a plain JSON value (None for absent)."""
    if value is None:
        return None
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return None if value != value else float(value)
    if hasattr(value, "isoformat"):
        return value.isoformat()
    try:
        import pandas as pd

        if pd.isna(value):
            return None
    except (TypeError, ValueError):
        pass
    return value
