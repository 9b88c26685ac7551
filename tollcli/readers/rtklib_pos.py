"""RTKLIB solution files (``.pos``, as ``rnx2rtkp``, ``rtkpost`` and ``rtknavi`` write them) → the epoch table.

A solution line, after ``%`` header lines that name the columns::

    %  GPST          latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio
    2021/04/29 20:17:51.000   37.416630843 -122.080990520   -2.7133   5   8   3.1234   2.4422   6.3921  -1.2037   2.0117  -3.4002   0.00    0.0

Time: ``yyyy/mm/dd hh:mm:ss.sss`` or ``week tow`` (``-t``-less output of older versions), in GPST (leap seconds
removed here), UTC or JST (the header's first column says which). Position: latitude/longitude in degrees
(``-g`` d m s too) or ECEF x/y/z (``-e``, converted). ``Q`` (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP)
becomes the GGA quality (4, 5, 2, 2, 1, 1: PPP is no differential fix in GGA's terms), ``ns`` the satellites
used. ``sdn``/``sde``/``sdu`` and ``sdne`` (RTKLIB writes the signed square root of the covariance) are the
solution's own standard deviations: read as a receiver-reported error ellipse (the GST columns
``sigma_lat_m``, ``sigma_lon_m``, ``sigma_alt_m``, ``sigma_major_m``, ``sigma_minor_m``, ``ellipse_orient_deg``),
so the ``gst`` integrity source bounds each position — the covariance level: RTKLIB's estimate of its own error,
no residual test. ``vn``/``ve`` velocities (``out-outvel``) give ``speed_mps`` and ``course_deg``.

A line that does not parse as the header announced is malformed: skipped and counted, an error with ``--strict``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from tollcli.errors import DataError
from tollcli.readers.nav_tables import TableBuilder, skip_malformed, text_line_blocks
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.nmea.reader import CHUNK_EPOCHS, NmeaTables
from tollcli.times import PLAUSIBLE_MS

#: RTKLIB's solution quality Q → GGA fix quality
Q_TO_GGA = {1: 4, 2: 5, 3: 2, 4: 2, 5: 1, 6: 1}
Q_NAMES = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}
#: Q → NMEA mode indicator (R RTK fixed, F float, D differential, A autonomous, P precise)
Q_MODE = {1: "R", 2: "F", 3: "D", 4: "D", 5: "A", 6: "P"}
#: time-system offsets from UTC (s): what is subtracted to get UTC (GPST: the leap seconds, looked up by date)
_JST_S = 9 * 3600
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ms")


class _Layout:
    """Where each field is on a solution line, from the header's column line."""

    def __init__(self, header: str, where: str) -> None:
        names = header.lstrip("%").split()
        if not names:
            raise DataError(f"{where}: an RTKLIB header without column names")
        self.timesys = names[0]  # GPST, UTC, JST
        if self.timesys not in ("GPST", "UTC", "JST"):
            raise DataError(f"{where}: RTKLIB time system {self.timesys!r}: GPST, UTC or JST are read")
        cols = names[1:]
        self.ecef = bool(cols) and cols[0].startswith("x-ecef")
        self.dms = bool(cols) and "(d'\")" in cols[0]
        if not (self.ecef or (cols and cols[0].startswith("latitude"))):
            raise DataError(f"{where}: RTKLIB positions as {cols[0] if cols else 'nothing'!r}: latitude/longitude or ECEF are read "
                            "(write the file without -a, the baseline)")
        self.cols = [c.split("(")[0] for c in cols]  # latitude, longitude, height, Q, ns, sdn, …

    def index(self, name: str) -> int | None:
        return self.cols.index(name) if name in self.cols else None


def _utc_ms(date_or_week: str, time_or_tow: str, timesys: str) -> int:
    """A solution's time as UTC ms since 1970."""
    if "/" in date_or_week:
        stamp = np.datetime64(date_or_week.replace("/", "-") + "T" + time_or_tow, "ms")
    else:
        stamp = _GPS_EPOCH + np.timedelta64(int(date_or_week) * 7 * 86_400_000 + round(float(time_or_tow) * 1000), "ms")
    ms = int(stamp.astype(np.int64))
    if not PLAUSIBLE_MS[0] <= ms < PLAUSIBLE_MS[1]:  # year 0, 60000: a damaged field (malformed line)
        raise ValueError(f"a time outside 1980–2200 ({date_or_week} {time_or_tow})")
    if timesys == "GPST":
        from tollcli.readers.gps_time import gps_millis_to_utc

        ms = int(gps_millis_to_utc(np.array([ms - int(_GPS_EPOCH.astype(np.int64))])).astype(np.int64)[0])
    elif timesys == "JST":
        ms -= _JST_S * 1000
    return ms


def _dms(d: str, m: str, s: str) -> float:
    deg = abs(float(d)) + float(m) / 60 + float(s) / 3600
    return -deg if d.strip().startswith("-") else deg


def ellipse(sdn: float, sde: float, sdne: float) -> tuple[float, float, float]:
    """(σ major, σ minor (m), orientation of the major axis (deg from north, clockwise)) of RTKLIB's sdn, sde, sdne."""
    c = math.copysign(sdne * sdne, sdne)  # RTKLIB writes sign(c)·sqrt(|c|)
    cov = np.array([[sde * sde, c], [c, sdn * sdn]])  # east, north
    values, vectors = np.linalg.eigh(cov)
    major = vectors[:, 1]
    orient = math.degrees(math.atan2(major[0], major[1])) % 180.0
    return math.sqrt(max(values[1], 0.0)), math.sqrt(max(values[0], 0.0)), orient


def _fields(parts: list[str], layout: _Layout) -> tuple[int, dict]:
    """(UTC ms, epoch-table fields) of one solution line's tokens."""
    when = _utc_ms(parts[0], parts[1], layout.timesys)  # the time is two tokens: date and time, or week and TOW
    rest = parts[2:]
    if layout.dms:  # latitude and longitude as d m s: three tokens each
        lat, lon, rest = _dms(*rest[0:3]), _dms(*rest[3:6]), [None, None, *rest[6:]]
    elif layout.ecef:
        from tollcli.geodesy import ecef2geodetic

        lat, lon, h = ecef2geodetic(float(rest[0]), float(rest[1]), float(rest[2]))
        rest = [lat, lon, h, *rest[3:]]
        lat, lon = float(lat), float(lon)
    else:
        lat, lon = float(rest[0]), float(rest[1])

    def col(name: str) -> float:
        i = layout.index(name)
        return float(rest[i]) if i is not None and i < len(rest) and rest[i] is not None else math.nan

    q = int(col("Q"))
    height = float(rest[2])
    fields = {"lat_deg": lat, "lon_deg": lon, "alt_m": height, "fix_quality": Q_TO_GGA.get(q, 0),
              "fix_mode": 3 if q in Q_TO_GGA else 1, "fix_valid": q in Q_TO_GGA, "mode_indicator": Q_MODE.get(q, "N")}
    ns = col("ns")
    if math.isfinite(ns):
        fields["n_used"] = int(ns)
    sdn, sde, sdu, sdne = col("sdn"), col("sde"), col("sdu"), col("sdne")
    if layout.ecef:  # sdx, sdy, sdz: not a horizontal ellipse; read none rather than a wrong one
        sdn = sde = sdu = sdne = math.nan
    if math.isfinite(sdn) and math.isfinite(sde):
        major, minor, orient = ellipse(sdn, sde, sdne if math.isfinite(sdne) else 0.0)
        fields.update(sigma_lat_m=sdn, sigma_lon_m=sde, sigma_major_m=major, sigma_minor_m=minor, ellipse_orient_deg=orient)
    if math.isfinite(sdu):
        fields["sigma_alt_m"] = sdu
    vn, ve = col("vn"), col("ve")
    if math.isfinite(vn) and math.isfinite(ve):
        fields["speed_mps"] = math.hypot(vn, ve)
        fields["course_deg"] = math.degrees(math.atan2(ve, vn)) % 360.0
    return when, fields


def iter_rtklib_pos_tables(source: str | os.PathLike | BinaryIO, *, strict: bool = False, stats: ReadStats | None = None,
                           chunk_epochs: int = CHUNK_EPOCHS) -> Iterator[NmeaTables]:  # fmt: skip
    """The epoch tables of an RTKLIB solution file, chunk by chunk (no satellite rows: a .pos file has none)."""
    stats = stats if stats is not None else ReadStats()
    builder = TableBuilder(stats)
    layout: _Layout | None = None
    for block in text_line_blocks(source, stats):
        for line_no, text in block:
            if text.startswith("%"):
                stats.comments += 1
                body = text.lstrip("%").split()
                if body and body[0] in ("GPST", "UTC", "JST") and len(body) > 2:
                    layout = _Layout(text, f"{stats.source}:{line_no}")
                continue
            try:
                if layout is None:
                    raise ValueError("a solution before the header naming its columns")
                when, fields = _fields(text.split(), layout)
            except (ValueError, IndexError, OverflowError) as exc:
                skip_malformed(stats, line_no, f"not an RTKLIB solution line ({exc})", strict)
                continue
            stats.sentences += 1
            stats.decoded += 1
            builder.add_epoch(when, line_no, **fields)
        if len(builder) >= chunk_epochs:
            tables = builder.take()
            if tables is not None:
                yield tables
    tables = builder.take()
    if tables is not None:
        yield tables
    elif stats.sentences == 0 and layout is not None:
        raise DataError(f"{stats.source}: an RTKLIB solution file without one solution (RTKLIB found none: "
                        "no navigation data for the observations' time?)")
