"""u-blox navigation messages → the epoch and satellite tables of the NMEA reader, streamed in chunks.

What a u-blox receiver reports about its own fix, message by message (offsets and scales of the u-blox
interface description; pyubx2's definitions agree, ``tests/test_ubx_nav.py`` checks it):

* ``NAV-PVT`` (0x01 0x07): UTC date and time, fix type and flags (``gnssFixOK``, ``diffSoln``, ``carrSoln``),
  satellites used, position, height above the ellipsoid and mean sea level, ground speed, heading of motion,
  PDOP, and ``hAcc`` — the receiver's horizontal accuracy estimate (m);
* ``NAV-SOL`` (0x01 0x06, older receivers): GPS week and time, fix, ECEF position and velocity, 3-D accuracy,
  PDOP; ``NAV-POSLLH`` (0x01 0x02): position and ``hAcc``; ``NAV-DOP`` (0x01 0x04): HDOP, VDOP, PDOP;
* ``NAV-SAT`` (0x01 0x35) and ``NAV-SVINFO`` (0x01 0x30, older): per satellite its elevation, azimuth, C/N0,
  whether the fix used it, and its **pseudorange residual** ``prRes`` (m) — the same information as an NMEA
  GSV + GSA + GRS, so the residual test runs on it exactly as on GRS;
* ``NAV-PL`` (0x01 0x62, protection-level firmware): the receiver's own protection level at its target
  integrity risk, read as a receiver-reported bound (σ = PL / K_H(TIR));
* ``HNR-PVT`` (0x28 0x02): the high-rate fused (dead-reckoning) solution of automotive modules (NEO-M8L/M8U);
  read only from logs without NAV positions (it carries no satellites: its epochs are bounded by ``hAcc`` alone).

Messages of one navigation epoch share their ``iTOW`` (GPS time of week, ms): consecutive messages with the
same ``iTOW`` make one epoch; an epoch without a position is dropped. Where NAV-PVT gives no valid date,
the UTC time comes from the GPS week (NAV-SOL, NAV-TIMEGPS) and the leap seconds (NAV-TIMEGPS, else the
table). ``line`` is the number of the epoch's first UBX message in the file (1-based).

Frames with a wrong checksum or a length their message cannot have are skipped and counted
(``bad_checksum``, ``malformed``); ``--strict`` makes the first one an error naming the message. Bytes between
frames (NMEA, RTCM, text) are another protocol on the same port: counted as ``not_nmea`` lines are not, they are
not errors.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from tollcli.errors import DataError
from tollcli.io.sources import open_binary, source_name
from tollcli.readers.gps_time import LEAP_SECONDS
from tollcli.readers.nav_tables import TableBuilder
from tollcli.readers.ubx_frames import SYNC, iter_frames
from tollcli.times import plausible_date
from tollcli.readers.nmea.line_reader import ReadStats
from tollcli.readers.nmea.reader import CHUNK_EPOCHS, NmeaTables

NAV_PVT, NAV_SOL, NAV_POSLLH, NAV_DOP = (0x01, 0x07), (0x01, 0x06), (0x01, 0x02), (0x01, 0x04)
NAV_SAT, NAV_SVINFO, NAV_PL, NAV_TIMEGPS, HNR_PVT = (0x01, 0x35), (0x01, 0x30), (0x01, 0x62), (0x01, 0x20), (0x28, 0x02)
#: messages that give an epoch its position
POSITION_MESSAGES = (NAV_PVT, NAV_SOL, NAV_POSLLH, HNR_PVT)
#: the shortest payload each message read here can have
MIN_LENGTH = {NAV_PVT: 84, NAV_SOL: 52, NAV_POSLLH: 28, NAV_DOP: 18, NAV_SAT: 8, NAV_SVINFO: 8, NAV_PL: 28, NAV_TIMEGPS: 16,
              HNR_PVT: 72}  # fmt: skip
#: UBX gnssId → constellation
GNSS_NAME = {0: "GPS", 1: "SBAS", 2: "Galileo", 3: "BeiDou", 5: "QZSS", 6: "GLONASS", 7: "NavIC"}
_EPOCH_1970_MS = 315_964_800_000  # 1980-01-06 in ms since 1970
_WEEK_MS = 604_800_000


def _leap_s(gps_ms: int) -> int:
    """GPS − UTC (s) at a GPS time (ms since 1970) from the leap-second table."""
    leap = 0
    for date, seconds in LEAP_SECONDS:
        if gps_ms >= int(np.datetime64(date, "ms").astype(np.int64)) + seconds * 1000:
            leap = seconds
    return leap


class _State:
    """What the messages of earlier epochs told: the GPS week, the leap seconds, whether HNR is read."""

    def __init__(self, use_hnr: bool) -> None:
        self.week = -1
        self.leap_s: int | None = None
        self.last_itow = -1
        self.use_hnr = use_hnr


def _utc_from_week(state: _State, itow_ms: int) -> int | None:
    if state.week < 0:
        return None
    if state.last_itow >= 0 and itow_ms < state.last_itow - _WEEK_MS // 2:  # the week rolled over since
        state.week += 1
    state.last_itow = itow_ms
    gps_ms = _EPOCH_1970_MS + state.week * _WEEK_MS + itow_ms
    leap = state.leap_s if state.leap_s is not None else _leap_s(gps_ms)
    return gps_ms - leap * 1000


def _quality(fix_type: int, gnss_ok: bool, diff: bool, carrier: int) -> tuple[int, int, bool, str]:
    """(GGA quality, GSA mode, fix valid, mode letter) of a u-blox fix type and flags."""
    if fix_type == 1:
        return 6, 1, False, "E"
    if fix_type in (2, 3, 4) and gnss_ok:
        quality = 4 if carrier == 2 else 5 if carrier == 1 else 2 if diff else 1
        return quality, 2 if fix_type == 2 else 3, True, "D" if diff else "A"
    return 0, 1, False, "N"


def _utc_ms(year: int, month: int, day: int, hour: int, minute: int, sec: int, nano: int, valid: int) -> int | None:
    """UTC ms since 1970 of a NAV-PVT / HNR-PVT date and time, None unless its ``valid`` flags say date and time."""
    if valid & 0x03 != 0x03 or not plausible_date(year, month, day, hour, minute, sec):
        return None
    try:
        base = int(np.datetime64(f"{year:04d}-{month:02d}-{day:02d}", "ms").astype(np.int64))
    except ValueError:
        return None
    return base + ((hour * 60 + minute) * 60 + sec) * 1000 + int(round(nano / 1e6))


def _pvt(p: bytes, state: _State) -> tuple[int | None, dict]:
    itow, year, month, day, hour, minute, sec, valid = struct.unpack_from("<IHBBBBBB", p, 0)
    nano, fix_type, flags, _, num_sv, lon, lat, height, hmsl, hacc = struct.unpack_from("<iBBBBiiiiI", p, 16)
    gspeed, head = struct.unpack_from("<ii", p, 60)
    pdop = struct.unpack_from("<H", p, 76)[0]
    quality, mode, ok, letter = _quality(fix_type, bool(flags & 1), bool(flags & 2), (flags >> 6) & 3)
    when = _utc_ms(year, month, day, hour, minute, sec, nano, valid)
    if when is None:
        when = _utc_from_week(state, itow)
    fields = dict(lat_deg=lat * 1e-7, lon_deg=lon * 1e-7, alt_m=hmsl / 1000.0, geoid_sep_m=(height - hmsl) / 1000.0,
                  fix_quality=quality, fix_mode=mode, fix_valid=ok, mode_indicator=letter, n_used=num_sv,
                  pdop=pdop * 0.01, speed_mps=gspeed / 1000.0, course_deg=(head * 1e-5) % 360.0,
                  sigma_major_m=hacc / 1000.0)  # fmt: skip
    if fix_type in (0, 5):
        fields.update(lat_deg=math.nan, lon_deg=math.nan)
    return when, fields


def _hnr(p: bytes, state: _State) -> tuple[int | None, dict]:
    itow, year, month, day, hour, minute, sec, valid, nano, fix, flags = struct.unpack_from("<IHBBBBBBiBB", p, 0)
    lon, lat, height, hmsl, gspeed, _, head = struct.unpack_from("<iiiiiii", p, 20)
    hacc = struct.unpack_from("<I", p, 52)[0]
    quality, mode, ok, letter = _quality(fix, bool(flags & 1), bool(flags & 2), 0)
    when = _utc_ms(year, month, day, hour, minute, sec, nano, valid)
    fields = dict(lat_deg=lat * 1e-7, lon_deg=lon * 1e-7, alt_m=hmsl / 1000.0, geoid_sep_m=(height - hmsl) / 1000.0,
                  fix_quality=quality, fix_mode=mode, fix_valid=ok, mode_indicator=letter, speed_mps=gspeed / 1000.0,
                  course_deg=(head * 1e-5) % 360.0, sigma_major_m=hacc / 1000.0)  # fmt: skip
    if fix in (0, 5):
        fields.update(lat_deg=math.nan, lon_deg=math.nan)
    return (when if when is not None else _utc_from_week(state, itow)), fields


def _sol(p: bytes, state: _State) -> tuple[int | None, dict]:
    from tollcli.geodesy import ecef2geodetic, enu_rotation

    itow, _, week, fix, flags, x, y, z, _, vx, vy, vz, _, pdop, _, num_sv = struct.unpack_from("<IihBBiiiIiiiIHBB", p, 0)
    if flags & 0x04 and week > 0:  # week valid
        state.week = week
    lat, lon, h = (float(v) for v in ecef2geodetic(x / 100.0, y / 100.0, z / 100.0))
    east, north, _ = enu_rotation(lat, lon) @ np.array([vx, vy, vz]) / 100.0
    quality, mode, ok, letter = _quality(fix, bool(flags & 1), bool(flags & 2), 0)
    fields = dict(lat_deg=lat, lon_deg=lon, fix_quality=quality, fix_mode=mode, fix_valid=ok, mode_indicator=letter,
                  n_used=num_sv, pdop=pdop * 0.01, speed_mps=math.hypot(east, north),
                  course_deg=math.degrees(math.atan2(east, north)) % 360.0)  # fmt: skip
    if fix in (0, 5) or (x, y, z) == (0, 0, 0):
        fields.update(lat_deg=math.nan, lon_deg=math.nan)
    return _utc_from_week(state, itow), fields


def _posllh(p: bytes, state: _State) -> tuple[int | None, dict]:
    itow, lon, lat, height, hmsl, hacc = struct.unpack_from("<IiiiiI", p, 0)
    return _utc_from_week(state, itow), dict(lat_deg=lat * 1e-7, lon_deg=lon * 1e-7, alt_m=hmsl / 1000.0,
                                             geoid_sep_m=(height - hmsl) / 1000.0, sigma_major_m=hacc / 1000.0)  # fmt: skip


def svinfo_satellite(number: int) -> tuple[str, int]:
    """(constellation, svid) of a satellite in u-blox's legacy one-space numbering (NAV-SVINFO)."""
    if 1 <= number <= 32:
        return "GPS", number
    if 33 <= number <= 64:
        return "BeiDou", number - 27
    if 65 <= number <= 96:
        return "GLONASS", number - 64
    if 120 <= number <= 158:
        return "SBAS", number
    if 159 <= number <= 163:
        return "BeiDou", number - 158
    if 193 <= number <= 202:
        return "QZSS", number - 192
    if 211 <= number <= 246:
        return "Galileo", number - 210
    return "unknown", number


def _satellites(ident: tuple[int, int], p: bytes) -> list[tuple[str, int, float, float, float, bool, float]]:
    """(constellation, svid, elev, azim, C/N0, used, residual) of each satellite of a NAV-SAT / NAV-SVINFO."""
    out = []
    count = p[5] if ident == NAV_SAT else p[4]
    for k in range(min(count, (len(p) - 8) // 12)):
        at = 8 + 12 * k
        if ident == NAV_SAT:
            gnss, svid, cno, elev, azim, pr_res, flags = struct.unpack_from("<BBBbhhI", p, at)
            name, used, residual = GNSS_NAME.get(gnss, "unknown"), bool(flags & 0x08), pr_res * 0.1
        else:
            _, number, flags, _, cno, elev, azim, pr_res = struct.unpack_from("<BBBBBbhi", p, at)
            (name, svid), used, residual = svinfo_satellite(number), bool(flags & 0x01), pr_res / 100.0
        known = -90 <= elev <= 90 and not (elev == 0 and azim == 0 and cno == 0)
        out.append((name, svid, float(elev) if known else math.nan, float(azim % 360) if known else math.nan,
                    float(cno) if cno > 0 else math.nan, used, residual if used else math.nan))  # fmt: skip
    return out


def _protection_sigma_m(p: bytes) -> float:
    """σ_major (m) a NAV-PL horizontal protection level stands for: PL_H / K_H(TIR) (NaN when not valid)."""
    _, coeff, exp, pos_valid, frame_kind = struct.unpack_from("<BBbBB", p, 0)
    pl1, pl2 = struct.unpack_from("<II", p, 16)
    tir = coeff * 10.0**exp
    if not pos_valid or frame_kind == 0 or not 0.0 < tir < 0.5:
        return math.nan
    return math.hypot(pl1, pl2) / 1000.0 / math.sqrt(-2.0 * math.log(tir))


def iter_ubx_nav_tables(source: str | os.PathLike | BinaryIO, *, strict: bool = False, stats: ReadStats | None = None,
                        chunk_epochs: int = CHUNK_EPOCHS, use_hnr: bool | None = None) -> Iterator[NmeaTables]:  # fmt: skip
    """The log's epoch and satellite tables, chunk by chunk (see the module's description).

    ``use_hnr``: read HNR-PVT epochs (default: only when the log's first MiB has no NAV position message)."""
    stats = stats if stats is not None else ReadStats()
    name = source_name(source)
    stats.source = name
    stream = open_binary(source)
    try:
        if use_hnr is None:
            head = stream.peek(1 << 20)[: 1 << 20] if hasattr(stream, "peek") else b""
            use_hnr = not any(bytes((SYNC[0], SYNC[1], c, i)) in head for c, i in POSITION_MESSAGES[:3])
        yield from _tables(stream, name, stats, strict, chunk_epochs, _State(use_hnr))
    finally:
        if isinstance(source, (str, os.PathLike)) and os.fspath(source) != "-":
            stream.close()


def _tables(stream: BinaryIO, name: str, stats: ReadStats, strict: bool, chunk_epochs: int, state: _State) -> Iterator[NmeaTables]:
    builder = TableBuilder(stats)
    epoch: dict | None = None  # the epoch being gathered: itow, time, line, fields, satellites

    def close(current: dict | None) -> None:
        if current is None or "lat_deg" not in current["fields"]:
            return
        fields = current["fields"]
        protection = fields.pop("protection_sigma_m", math.nan)
        if math.isfinite(protection):  # the receiver's protection level: a bound no smaller than hAcc's
            fields["sigma_major_m"] = max(protection, fields.get("sigma_major_m", 0.0) if _known(fields.get("sigma_major_m", math.nan)) else 0.0)
        if current["sats"] is not None:
            fields["n_in_view"] = len(current["sats"])
        index = builder.add_epoch(current["time"], current["line"], **fields)
        for sat in current["sats"] or ():
            builder.add_satellite(index, *sat)
        stats.decoded += 1

    for cls, ident, payload, number in iter_frames(stream, name, stats, strict):
        key = (cls, ident)
        if key not in MIN_LENGTH:
            stats.unused += 1
            stats.unused_types[f"UBX-{cls:02X}-{ident:02X}"] = stats.unused_types.get(f"UBX-{cls:02X}-{ident:02X}", 0) + 1
            continue
        if len(payload) < MIN_LENGTH[key] or (key in (NAV_SAT, NAV_SVINFO) and len(payload) < 8 + 12 * (payload[5] if key == NAV_SAT else payload[4])):
            stats.malformed += 1
            if not stats.first_problem:
                stats.first_problem = f"{name}: UBX message {number}: {len(payload)}-byte payload too short"
            if strict:
                raise DataError(f"{name}: UBX message {number} (class 0x{cls:02X} id 0x{ident:02X}): "
                                f"{len(payload)}-byte payload too short for its message")  # fmt: skip
            continue
        if key == NAV_TIMEGPS:
            _, _, week, leap, valid = struct.unpack_from("<IihbB", payload, 0)
            if valid & 0x02 and week > 0:
                state.week = week
            if valid & 0x04:
                state.leap_s = int(leap)
            continue
        if key == HNR_PVT and not state.use_hnr:
            stats.unused += 1
            continue
        itow = struct.unpack_from("<I", payload, 12 if key == NAV_PL else 0)[0]
        if epoch is None or itow != epoch["itow"]:
            close(epoch)
            if len(builder) >= chunk_epochs:
                tables = builder.take()
                if tables is not None:
                    yield tables
            epoch = {"itow": itow, "time": None, "line": number, "fields": {}, "sats": None}
        if key in POSITION_MESSAGES:
            when, fields = {NAV_PVT: _pvt, NAV_SOL: _sol, NAV_POSLLH: _posllh, HNR_PVT: _hnr}[key](payload, state)
            if "lat_deg" in epoch["fields"] and key != NAV_PVT:
                fields = {k: v for k, v in fields.items() if k not in epoch["fields"] or not _known(epoch["fields"][k])}
            epoch["fields"].update(fields)
            if epoch["time"] is None or key == NAV_PVT:
                epoch["time"] = when if when is not None else epoch["time"]
        elif key == NAV_DOP:
            _, _, pdop, _, vdop, hdop = struct.unpack_from("<IHHHHH", payload, 0)
            epoch["fields"].update(hdop=hdop * 0.01, vdop=vdop * 0.01, pdop=pdop * 0.01)
        elif key in (NAV_SAT, NAV_SVINFO):
            if epoch["sats"] is None or key == NAV_SAT:  # NAV-SAT is the newer, more complete one
                epoch["sats"] = _satellites(key, payload)
        elif key == NAV_PL:
            sigma = _protection_sigma_m(payload)
            if math.isfinite(sigma):
                epoch["fields"]["protection_sigma_m"] = sigma
    close(epoch)
    tables = builder.take()
    if tables is not None:
        yield tables


def _known(value) -> bool:
    return not (isinstance(value, float) and math.isnan(value)) and value != -1

