"""Compose NMEA 0183 sentences from values (the reader's inverse).

Used for round-trip tests, benchmark logs and bundled samples; the simulator
writes its logs through the same functions. Units as in the tables: degrees,
metres, seconds of day, m/s.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterator, Sequence

from tollcli.readers.nmea.fields import KNOT_MPS, checksum


def with_checksum(body: str) -> str:
    """``GPGGA,...`` → ``$GPGGA,...*HH``."""
    return f"${body}*{checksum(body):02X}"


def hhmmss(tod_s: float, decimals: int = 2) -> str:
    """Seconds of day → ``hhmmss.ss``."""
    tod_s = round(tod_s, decimals)
    hh, rest = divmod(tod_s, 3600.0)
    mm, ss = divmod(rest, 60.0)
    return f"{int(hh):02d}{int(mm):02d}{ss:0{3 + decimals}.{decimals}f}"


def _degrees_minutes(value_deg: float, width: int, decimals: int) -> str:
    a = abs(value_deg)
    d = int(a)
    m = round((a - d) * 60.0, decimals)
    if m >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{width}d}{m:0{3 + decimals}.{decimals}f}"


def ddmm(lat_deg: float, decimals: int = 7) -> tuple[str, str]:
    """Latitude → (``ddmm.mmmmmmm``, N/S)."""
    return _degrees_minutes(lat_deg, 2, decimals), "S" if lat_deg < 0 else "N"


def dddmm(lon_deg: float, decimals: int = 7) -> tuple[str, str]:
    """Longitude → (``dddmm.mmmmmmm``, E/W)."""
    return _degrees_minutes(lon_deg, 3, decimals), "W" if lon_deg < 0 else "E"


def _f(value: float | None, fmt: str) -> str:
    return "" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, fmt)


def gga(tod_s: float, lat_deg: float, lon_deg: float, quality: int = 1, n_used: int = 8,
        hdop: float = 1.0, alt_m: float = 0.0, geoid_sep_m: float = 0.0, talker: str = "GN") -> str:  # fmt: skip
    lat, ns = ddmm(lat_deg)
    lon, ew = dddmm(lon_deg)
    return with_checksum(
        f"{talker}GGA,{hhmmss(tod_s)},{lat},{ns},{lon},{ew},{quality},{n_used:02d},"
        f"{_f(hdop, '.2f')},{_f(alt_m, '.3f')},M,{_f(geoid_sep_m, '.3f')},M,,"
    )


def rmc(tod_s: float, lat_deg: float, lon_deg: float, speed_mps: float, course_deg: float,
        date: _dt.date, status: str = "A", mode: str = "A", talker: str = "GN") -> str:  # fmt: skip
    lat, ns = ddmm(lat_deg)
    lon, ew = dddmm(lon_deg)
    return with_checksum(
        f"{talker}RMC,{hhmmss(tod_s)},{status},{lat},{ns},{lon},{ew},{_f(speed_mps / KNOT_MPS, '.3f')},"
        f"{_f(course_deg, '.2f')},{date:%d%m%y},,,{mode}"
    )


def vtg(speed_mps: float, course_deg: float, talker: str = "GN") -> str:
    return with_checksum(
        f"{talker}VTG,{_f(course_deg, '.2f')},T,,M,{_f(speed_mps / KNOT_MPS, '.3f')},N,{_f(speed_mps * 3.6, '.3f')},K,A"
    )


def gsa(prns: Sequence[int], pdop: float, hdop: float, vdop: float, fix_mode: int = 3,
        system_id: int | None = None, talker: str = "GN") -> str:  # fmt: skip
    slots = [f"{p:02d}" for p in prns[:12]] + [""] * (12 - min(len(prns), 12))
    tail = f",{system_id}" if system_id is not None else ""
    return with_checksum(
        f"{talker}GSA,A,{fix_mode},{','.join(slots)},{pdop:.2f},{hdop:.2f},{vdop:.2f}{tail}"
    )


def gsv(sats: Sequence[tuple[int, float, float, float]], talker: str = "GP",
        signal_id: int | None = None) -> list[str]:  # fmt: skip
    """GSV sentences for ``(prn, elev_deg, azim_deg, cn0_dbhz)`` tuples, four per sentence."""
    total = max(1, math.ceil(len(sats) / 4))
    out = []
    for i in range(total):
        block = sats[4 * i : 4 * i + 4]
        groups = "".join(f",{p:02d},{_f(e, '.0f')},{_f(a, '03.0f')},{_f(c, '.0f')}" for p, e, a, c in block)
        tail = f",{signal_id:X}" if signal_id is not None else ""
        out.append(with_checksum(f"{talker}GSV,{total},{i + 1},{len(sats):02d}{groups}{tail}"))
    return out


def gst(tod_s: float, rms_m: float, sigma_major_m: float, sigma_minor_m: float, orient_deg: float,
        sigma_lat_m: float, sigma_lon_m: float, sigma_alt_m: float, talker: str = "GN") -> str:  # fmt: skip
    return with_checksum(
        f"{talker}GST,{hhmmss(tod_s)},{rms_m:.2f},{sigma_major_m:.2f},{sigma_minor_m:.2f},{orient_deg:.1f},"
        f"{sigma_lat_m:.2f},{sigma_lon_m:.2f},{sigma_alt_m:.2f}"
    )


def grs(tod_s: float, residuals_m: Sequence[float], system_id: int | None = None, talker: str = "GN") -> str:
    slots = [f"{r:.2f}" for r in residuals_m[:12]] + [""] * (12 - min(len(residuals_m), 12))
    tail = f",{system_id},1" if system_id is not None else ""
    return with_checksum(f"{talker}GRS,{hhmmss(tod_s)},1,{','.join(slots)}{tail}")


def zda(tod_s: float, date: _dt.date, talker: str = "GN") -> str:
    return with_checksum(f"{talker}ZDA,{hhmmss(tod_s)},{date.day:02d},{date.month:02d},{date.year:04d},00,00")


def straight_drive(
    n_epochs: int,
    start: _dt.datetime = _dt.datetime(2024, 5, 6, 8, 0, 0, tzinfo=_dt.UTC),
    lat_deg: float = 42.6987,
    lon_deg: float = 2.8956,
    speed_mps: float = 13.9,
    course_deg: float = 45.0,
) -> Iterator[str]:
    """Lines of a plain 1 Hz GPS+Galileo drive along a rhumb line (NMEA 4.10 style).

    Per epoch: RMC, VTG, GGA, GSA (GPS, Galileo, with system ids), GSV (GP, GA,
    with signal ids), GST. The geometry is fixed and schematic, not an orbit
    model: a load for readers and benchmarks, and a small bundled sample.
    """
    gps = [(3, 62.0, 45.0, 44.0), (7, 35.0, 130.0, 41.0), (9, 48.0, 250.0, 42.0), (16, 21.0, 310.0, 37.0),
           (22, 15.0, 200.0, 35.0), (27, 70.0, 90.0, 45.0), (30, 28.0, 20.0, 39.0)]  # fmt: skip
    gal = [(2, 55.0, 170.0, 43.0), (11, 30.0, 280.0, 40.0), (24, 40.0, 60.0, 42.0), (36, 18.0, 340.0, 36.0)]
    m_per_deg_lat = 111_132.0
    m_per_deg_lon = 111_320.0 * math.cos(math.radians(lat_deg))
    d_north = speed_mps * math.cos(math.radians(course_deg))
    d_east = speed_mps * math.sin(math.radians(course_deg))
    t0 = start.hour * 3600 + start.minute * 60 + start.second
    for k in range(n_epochs):
        day, tod = divmod(t0 + k, 86_400)
        date = start.date() + _dt.timedelta(days=day)
        lat = lat_deg + k * d_north / m_per_deg_lat
        lon = lon_deg + k * d_east / m_per_deg_lon
        yield rmc(tod, lat, lon, speed_mps, course_deg, date)
        yield vtg(speed_mps, course_deg)
        yield gga(tod, lat, lon, 1, len(gps) + len(gal), 0.9, 35.0, 49.5)
        yield gsa([p for p, *_ in gps], 1.6, 0.9, 1.3, system_id=1)
        yield gsa([p for p, *_ in gal], 1.6, 0.9, 1.3, system_id=3)
        yield from gsv(gps, "GP", signal_id=1)
        yield from gsv(gal, "GA", signal_id=7)
        yield gst(tod, 2.1, 3.0, 2.0, 30.0, 2.6, 2.4, 4.5)
