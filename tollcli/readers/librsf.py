"""libRSF text logs (TU Chemnitz smartLoc as the libRSF project distributes it), read into tables.

Each line is one measurement, its kind first (the data set's ``readme.libRSF.txt``):

* ``pseudorange3 t pr var x y z sat sys elev cn0`` — a pseudorange (m) with atmosphere and satellite clock
  already removed, its variance (m²), the satellite's ECEF position at transmission (m, in the ECEF frame of
  that time), satellite id (GPS 1–32; Galileo 300 + PRN), system, elevation (deg), C/N0 (dB-Hz);
* ``odom3 t vx vy vz wx wy wz`` + 6 variances — the vehicle's odometry (m/s, rad/s, body frame);
* ``point3 t X Y Z`` + 9 zeros — the reference trajectory (ECEF, m): the ``_GT`` file.

Times are seconds from the start of the recording; the files carry no date. They are placed at
``LIBRSF_T0`` (1970-01-01T00:00:00Z) + t, in logs and truth alike, so the two stay comparable.
Lines of another kind are passed over; a line of a known kind whose fields are not numbers is malformed:
skipped and counted (``--strict``: an error naming its line).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError

LIBRSF_T0 = pd.Timestamp("1970-01-01T00:00:00Z")
KINDS = {"pseudorange3": 11, "odom3": 14, "point3": 14}  # fields per line, the kind included
PSEUDORANGE_COLUMNS = ("t_s", "pr_m", "pr_var_m2", "x_sv_m", "y_sv_m", "z_sv_m", "sat", "sys", "elev_deg", "cn0_dbhz")
ODOMETRY_COLUMNS = ("t_s", "vx_mps", "vy_mps", "vz_mps", "wx_radps", "wy_radps", "wz_radps")
POINT_COLUMNS = ("t_s", "x_m", "y_m", "z_m")


@dataclass
class LibrsfLog:
    pseudoranges: pd.DataFrame  # one row per satellite-epoch, PSEUDORANGE_COLUMNS
    odometry: pd.DataFrame  # ODOMETRY_COLUMNS
    points: pd.DataFrame  # POINT_COLUMNS (the ground-truth file)
    malformed: int  # lines of a known kind that were skipped


#: satellite numbers and system codes are below this (smartLoc: GPS 1–32, Galileo 301–336; systems 1 and 3)
SATELLITE_ID_LIMIT = 1000


def read_librsf(path: str, strict: bool = False) -> LibrsfLog:
    """The three kinds of measurement of a libRSF file as tables (rows in file order): its blocks
    (:func:`iter_librsf`) joined. Its fields are parsed as numbers as they are read; from a block with a field that is
    not one (a malformed line, or a line of another kind) on, the file is read as text, each line's fields then tried
    one by one (the same numbers: 8 times slower, and a Python string per field)."""
    parts = list(iter_librsf(path, strict))
    return LibrsfLog(*(pd.concat([getattr(p, name) for p in parts], ignore_index=True) for name in ("pseudoranges", "odometry", "points")),
                     sum(p.malformed for p in parts))  # fmt: skip


#: rows of a libRSF file parsed at a time by :func:`iter_librsf`
BLOCK_ROWS = 50_000


def iter_librsf(path: str, strict: bool = False, block_rows: int | None = None) -> Iterator[LibrsfLog]:
    """A libRSF file's tables :data:`BLOCK_ROWS` rows at a time, in file order, malformed lines counted (each in the
    part that holds it) and, with ``strict``, named by their row. Memory is a block's. A part with a field that is not
    a number is read again as text from its first row on, and so is the rest of the file."""
    block_rows = block_rows or BLOCK_ROWS
    row0, numbers, seen = 0, True, False
    while True:
        try:
            with _opened(path, numbers, block_rows) as reader:
                for raw in _rows_from(reader, row0):
                    part = _tables(raw.reset_index(drop=True), numbers, row0, path, strict)
                    row0 += len(raw)
                    seen |= bool(len(part.pseudoranges) or len(part.odometry) or len(part.points))
                    yield part
            break
        except ValueError as exc:  # a field that is not a number: this block and the rest read as text
            if not numbers or isinstance(exc, pd.errors.ParserError):
                raise DataError(f"{path}: not a readable libRSF text file ({str(exc).splitlines()[0]})") from None
            numbers = False
        except (OSError, UnicodeDecodeError) as exc:
            raise DataError(f"{path}: not a readable libRSF text file ({str(exc).splitlines()[0]})") from None
    if not seen:
        raise DataError(f"{path}: no pseudorange3, odom3 or point3 line: not a libRSF log")


def _csv_options(numbers: bool) -> dict:
    return {"sep": r"\s+", "header": None, "names": range(15), "engine": "c", "comment": "#",
            "dtype": {0: str, **dict.fromkeys(range(1, 15), np.float64)} if numbers else str}  # fmt: skip


def _opened(path: str, numbers: bool, block_rows: int):
    """A chunked reader of ``path`` (a context manager: closed on leaving)."""
    try:
        return pd.read_csv(path, chunksize=block_rows, **_csv_options(numbers))
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except pd.errors.EmptyDataError:
        raise DataError(f"{path}: empty: no libRSF measurements") from None


def _rows_from(reader, skip: int):
    """The blocks of ``reader`` from its row ``skip`` on (rows: the lines pandas reads, comments and blank lines not
    counted; those before ``skip`` were read already, as numbers)."""
    for raw in reader:
        if skip >= len(raw):
            skip -= len(raw)
            continue
        yield raw.iloc[skip:]
        skip = 0


def _tables(raw: pd.DataFrame, numbers: bool, row0: int, path: str, strict: bool) -> LibrsfLog:
    """The tables of the rows ``raw`` (the file's rows ``row0`` on; ``numbers``: parsed as numbers, else text)."""
    kind = raw[0].to_numpy(object)
    tables, malformed = {}, 0
    for name, columns in (("pseudorange3", PSEUDORANGE_COLUMNS), ("odom3", ODOMETRY_COLUMNS), ("point3", POINT_COLUMNS)):
        rows = np.flatnonzero(kind == name)
        values = raw.iloc[rows, 1 : 1 + len(columns)]
        values = (values if numbers else values.apply(pd.to_numeric, errors="coerce")).to_numpy(float)
        bad = ~np.isfinite(values).all(axis=1)
        if name == "pseudorange3":  # a satellite number (GPS 1…, Galileo 301…) and a system code are small integers
            ids = values[:, [columns.index("sat"), columns.index("sys")]]
            with np.errstate(invalid="ignore"):
                bad |= ~((ids >= 0) & (ids < SATELLITE_ID_LIMIT) & (np.floor(ids) == ids)).all(axis=1)
        if bad.any() and strict:
            raise DataError(f"{path}:{row0 + int(rows[np.argmax(bad)]) + 1}: a {name} line whose fields are not {len(columns)} numbers")
        malformed += int(bad.sum())
        tables[name] = pd.DataFrame(values[~bad], columns=list(columns))
    pr = tables["pseudorange3"]
    pr["sat"], pr["sys"] = pr["sat"].astype(np.int64), pr["sys"].astype(np.int64)
    return LibrsfLog(pr, tables["odom3"], tables["point3"], malformed)


def librsf_times(t_s) -> pd.DatetimeIndex:
    """UTC times of libRSF time stamps (seconds from the recording's start, placed at ``LIBRSF_T0``)."""
    return pd.DatetimeIndex(LIBRSF_T0 + pd.to_timedelta(np.round(np.asarray(t_s, float) * 1e3), unit="ms"))


def librsf_truth(path: str) -> pd.DataFrame:
    """A libRSF ground-truth file (``point3``) as a trajectory: ``time_utc``, ``lat_deg``, ``lon_deg``, ``height_m``."""
    from tollcli.geodesy import ecef2geodetic

    points = read_librsf(path).points
    if points.empty:
        raise DataError(f"{path}: no point3 line: not a libRSF ground-truth file")
    lat, lon, h = ecef2geodetic(points["x_m"].to_numpy(), points["y_m"].to_numpy(), points["z_m"].to_numpy())
    return pd.DataFrame({"time_utc": librsf_times(points["t_s"]), "lat_deg": lat, "lon_deg": lon, "height_m": h})
