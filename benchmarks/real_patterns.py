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
                decimals = len(fields[k].split(".")[1]) if "." in fields[k] else 0
                fields[k] = _hhmmss(t + shift, decimals)
                body = f"{address},{','.join(fields)}"
                batch.append(f"${body}*{checksum(body)}")
            fh.write("\n".join(batch) + "\n")
            written += len(batch)
            copy += 1
    return written
