"""Replays of real receivers' sentence patterns, re-timed into long logs (for the benchmarks).

A pattern is a real log from ``../shared/data/gpsd/`` (gpsd's regression suite, BSD-2-Clause,
not copied here): its checksummed NMEA sentences, in their order, with every sentence type,
talker, proprietary and text line the receiver wrote. :func:`replay` repeats that sequence
until the wanted number of lines, shifting every time of day (GGA, GNS, RMC, GLL, GST, GBS,
GRS, ZDA) so that copy k follows copy k − 1 by the log's own span plus one second, and
rewriting the checksums. The receiver's sentence mix, field layouts and quirks are kept;
only the clock moves on.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "gpsd"

#: make → a gpsd log with its sentence pattern (Septentrio: none in the shared data; Unicore in its place)
PATTERNS = {
    "u-blox ZED-F9P (GST+GBS)": "ublox-zed-f9p-nmea.log",
    "u-blox ZED-F9T (L5, GST+GBS)": "ublox-zed-f9t-ubx_nmea_l5.log",
    "u-blox NEO-M8N": "neo-m8n.log",
    "Quectel L70 (GST, GRS)": "quectel-L70.log",
    "Quectel LC79D (multi-signal GSV)": "quectelLC79D.log",
    "SiRF IV (GlobalSat BU-353-S4)": "bu353s4.log",
    "MediaTek MT3301": "mtk-3301.log",
    "SkyTraq (GST)": "skytraq-fix.log",
    "ST Teseo LIV4F (GST+GBS)": "st-teseo-liv4f.log",
    "Unicore UM621": "unicore-um621.log",
    "Telit PLS83 (GNS)": "telit-pls83-w.log",
}
_SENTENCE = re.compile(r"\$([A-Z0-9]{2,6}),([^*]*)\*([0-9A-Fa-f]{2})\s*$")
#: sentence type → index of its time-of-day field after the address
_TIME_FIELD = {"GGA": 0, "GNS": 0, "RMC": 0, "GST": 0, "GBS": 0, "GRS": 0, "ZDA": 0, "GLL": 4}


def checksum(body: str) -> str:
    c = 0
    for ch in body.encode("latin-1"):
        c ^= ch
    return f"{c:02X}"


def _tod(text: str) -> float | None:
    try:
        return int(text[0:2]) * 3600 + int(text[2:4]) * 60 + float(text[4:])
    except ValueError:
        return None


def _decimals(text: str) -> int:
    """Digits after the point of a number as the receiver wrote it (0 without a point)."""
    return len(text.split(".")[1]) if "." in text else 0


def _hhmmss(t: float, decimals: int) -> str:
    t %= 86_400.0
    h, rest = divmod(t, 3600.0)
    m, s = divmod(rest, 60.0)
    width = 3 + decimals if decimals else 2
    return f"{int(h):02d}{int(m):02d}{s:0{width}.{decimals}f}"


def template(log: Path) -> list[tuple[str, list[str], int, float | None]]:
    """The log's checksummed sentences: (address, fields, time field index or -1, time of day)."""
    out = []
    for raw in log.read_bytes().decode("latin-1").splitlines():
        m = _SENTENCE.search(raw)
        if not m or checksum(f"{m.group(1)},{m.group(2)}").upper() != m.group(3).upper():
            continue
        address, fields = m.group(1), m.group(2).split(",")
        k = _TIME_FIELD.get(address[2:], -1) if not address.startswith("P") else -1
        t = _tod(fields[k]) if 0 <= k < len(fields) and fields[k] else None
        out.append((address, fields, k if t is not None else -1, t))
    return out


def replay(log: Path, out: Path, min_lines: int) -> int:
    """Write ``log``'s pattern, re-timed, until at least ``min_lines`` lines; returns the number of lines."""
    lines = template(log)
    times = [t for *_, t in lines if t is not None]
    if not lines or not times:
        raise ValueError(f"{log}: no timed NMEA sentence")
    start, span = min(times), max(times) - min(times) + 1.0
    untimed = [None if k >= 0 else f"${address},{','.join(fields)}*{checksum(f'{address},{chr(44).join(fields)}')}"
               for address, fields, k, _ in lines]  # fmt: skip
    written = 0
    with open(out, "w", encoding="latin-1", newline="\n") as fh:
        copy = 0
        while written < min_lines:
            shift = copy * span - start  # every copy starts at midnight + copy × span
            batch = []
            for (address, fields, k, t), fixed in zip(lines, untimed):
                if fixed is not None:
                    batch.append(fixed)
                    continue
                fields = list(fields)
                fields[k] = _hhmmss(t + shift, _decimals(fields[k]))
                body = f"{address},{','.join(fields)}"
                batch.append(f"${body}*{checksum(body)}")
            fh.write("\n".join(batch) + "\n")
            written += len(batch)
            copy += 1
    return written


def first_band(epoch: list[tuple[str, list[str], int, float | None]]) -> list[tuple[str, list[str], int, float | None]]:
    """An epoch's sentences without the GSV lines of any signal but the first each talker reports (NMEA 4.10's signal
    id, the last field): what a single-band receiver of the same make writes — a dual-band u-blox ZED-F9P's epoch as a
    NEO-M9N would write it (12 GSV lines instead of 24)."""
    first: dict[str, str] = {}
    out = []
    for item in epoch:
        address, fields = item[0], item[1]
        if address[2:] == "GSV":
            signal = fields[-1] if (len(fields) - 3) % 4 == 1 else ""
            if first.setdefault(address[:2], signal) != signal:
                continue
        out.append(item)
    return out


def _epochs(lines: list[tuple[str, list[str], int, float | None]]) -> list[list[tuple[str, list[str], int, float | None]]]:
    """The template's sentences grouped into epochs (a new one where a time of day changes)."""
    out: list[list] = []
    current_t = None
    for item in lines:
        t = item[3]
        if not out or (t is not None and current_t is not None and abs(t - current_t) >= 5e-4):
            out.append([])
        if t is not None:
            current_t = t
        out[-1].append(item)
    return out


def _ddmm(value_deg: float, width: int, decimals: int) -> tuple[str, bool]:
    a = abs(value_deg)
    deg = int(a)
    minutes = (a - deg) * 60.0
    text = f"{deg:0{width}d}{minutes:0{3 + decimals}.{decimals}f}"
    return text, value_deg < 0


def drive(log: Path, out: Path, n_epochs: int, track, day0: tuple[int, int, int] = (6, 5, 2024), single_band: bool = False) -> int:
    """A drive of ``n_epochs`` 1 Hz epochs with ``log``'s sentences, on ``track``; returns the number of lines.
    ``single_band``: each epoch without the GSV lines of a constellation's second signal (:func:`first_band`).

    Epoch k is the log's epoch k mod (its number of epochs), as the receiver wrote it (satellites,
    GSA/GSV, GST, GBS, …), with its time set to k s after midnight of ``day0`` (d, m, y) and its
    position, speed and course (GGA, GNS, RMC, GLL, VTG) set to ``track(k)`` → (lat_deg, lon_deg,
    speed_mps, course_deg); RMC and ZDA dates follow the time.
    """
    import datetime as dt

    epochs = _epochs(template(log))
    if single_band:
        epochs = [first_band(e) for e in epochs]
    written = 0
    start = dt.datetime(day0[2], day0[1], day0[0])
    with open(out, "w", encoding="latin-1", newline="\n") as fh:
        for k in range(n_epochs):
            lat, lon, speed, course = track(k)
            when = start + dt.timedelta(seconds=k)
            batch = []
            for address, fields, i_time, _ in epochs[k % len(epochs)]:
                f = _moved(address[2:], list(fields), lat, lon, speed, course, when)
                body = f"{address},{','.join(f)}"
                batch.append(f"${body}*{checksum(body)}")
            fh.write("\n".join(batch) + "\n")
            written += len(batch)
    return written


#: sentence type → (time field, latitude field) after the address (-1: none)
_DRIVE_FIELDS = {"GGA": (0, 1), "GNS": (0, 1), "RMC": (0, 2), "GLL": (4, 0), "GST": (0, -1), "GBS": (0, -1),
                 "GRS": (0, -1), "ZDA": (0, -1)}  # fmt: skip


def _moved(kind: str, f: list[str], lat, lon, speed_mps, course_deg, when) -> list[str]:
    """One sentence's fields with the drive's time, position, speed, course and date."""
    t_field, lat_field = _DRIVE_FIELDS.get(kind, (-1, -1))
    if 0 <= t_field < len(f) and f[t_field]:
        f[t_field] = _hhmmss(when.hour * 3600 + when.minute * 60 + when.second, _decimals(f[t_field]))
    if 0 <= lat_field and lat_field + 3 < len(f) and f[lat_field] and f[lat_field + 2]:
        dec = _decimals(f[lat_field]) if "." in f[lat_field] else 4
        f[lat_field], south = _ddmm(lat, 2, dec)
        f[lat_field + 1] = "S" if south else "N"
        f[lat_field + 2], west = _ddmm(lon, 3, dec)
        f[lat_field + 3] = "W" if west else "E"
    knots = speed_mps * 3600.0 / 1852.0
    if kind == "RMC" and len(f) > 8:
        f[6], f[7], f[8] = f"{knots:.3f}", f"{course_deg:.2f}", when.strftime("%d%m%y")
    elif kind == "VTG" and len(f) > 6 and f[1] in ("T", ""):
        f[0], f[1], f[4], f[6] = f"{course_deg:.2f}", "T", f"{knots:.3f}", f"{speed_mps * 3.6:.3f}"
    elif kind == "ZDA" and len(f) > 3:
        f[1], f[2], f[3] = f"{when.day:02d}", f"{when.month:02d}", f"{when.year:04d}"
    return f


def ubx_epochs(log: Path) -> list[tuple[bytes, bytes]]:
    """(NAV-PVT payload, NAV-SAT payload) of every epoch of a real u-blox log that has both, in order."""
    from tollcli.readers.nmea import ReadStats
    from tollcli.readers.ubx_frames import iter_frames

    epochs, pvt, sat, itow = [], None, None, None
    with open(log, "rb") as fh:
        for cls, ident, payload, _ in iter_frames(fh, str(log), ReadStats(), False):
            if (cls, ident) not in ((0x01, 0x07), (0x01, 0x35)):
                continue
            t = int.from_bytes(payload[:4], "little")
            if t != itow:
                if pvt is not None and sat is not None:
                    epochs.append((pvt, sat))
                pvt = sat = None
                itow = t
            if ident == 0x07:
                pvt = payload
            else:
                sat = payload
    if pvt is not None and sat is not None:
        epochs.append((pvt, sat))
    return epochs


def ubx_drive(log: Path, out: Path, n_epochs: int, track, day0: tuple[int, int, int] = (6, 5, 2024),
              bias: tuple[int, int, float] | None = None) -> int:  # fmt: skip
    """A drive of ``n_epochs`` 1 Hz epochs replaying a real u-blox log's NAV-SAT (satellites, C/N0, used flags,
    prRes) and NAV-PVT (fix type, flags, hAcc, DOP) epoch by epoch, with each NAV-PVT's time, position, velocity
    and course set to ``track(k)`` (as :func:`drive` does for NMEA). ``bias`` (first epoch, last epoch, metres):
    added to the prRes of the first satellite the fix used in those epochs (a fault the residual test must see).
    Returns the number of frames written."""
    import datetime as dt
    import struct

    from tollcli.readers.ubx_frames import frame

    template = ubx_epochs(log)
    start = dt.datetime(day0[2], day0[1], day0[0])
    gps_epoch = dt.datetime(1980, 1, 6)
    written = 0
    with open(out, "wb") as fh:
        for k in range(n_epochs):
            pvt, sat = (bytearray(p) for p in template[k % len(template)])
            lat, lon, speed, course = track(k)
            when = start + dt.timedelta(seconds=k)
            itow = int(round(((when - gps_epoch).total_seconds() + 18) % 604_800 * 1000))
            struct.pack_into("<IHBBBBBB", pvt, 0, itow, when.year, when.month, when.day, when.hour, when.minute, when.second, 0x07)
            struct.pack_into("<i", pvt, 16, 0)
            struct.pack_into("<ii", pvt, 24, round(lon * 1e7), round(lat * 1e7))
            c = math.radians(course)
            struct.pack_into("<iii", pvt, 48, round(speed * math.cos(c) * 1000), round(speed * math.sin(c) * 1000), 0)
            struct.pack_into("<ii", pvt, 60, round(speed * 1000), round(course * 1e5))
            struct.pack_into("<I", sat, 0, itow)
            if bias is not None and bias[0] <= k <= bias[1]:
                for j in range(sat[5]):
                    at = 8 + 12 * j
                    if struct.unpack_from("<I", sat, at + 8)[0] & 0x08:  # the first used satellite
                        res = struct.unpack_from("<h", sat, at + 6)[0]
                        struct.pack_into("<h", sat, at + 6, res + round(bias[2] * 10))
                        break
            fh.write(frame(0x01, 0x35, bytes(sat)) + frame(0x01, 0x07, bytes(pvt)))
            written += 2
    return written
