"""u-blox UBX binary logs (pyubx2 frames and fields them) → raw-measurement, navigation-data and PVT tables.

* ``RXM-RAWX``: one row per measurement — receiver time of week and week (GPS time of the receiver's
  clock), pseudorange (m), carrier phase (cycles), Doppler (Hz), C/N0, standard deviations
  (0.01·2ⁿ m, 0.004 cycles, 0.002·2ⁿ Hz as the message codes them), tracking flags;
* ``RXM-SFRBX``: one row per navigation-data subframe (satellite and its ten 32-bit words), decoded
  into ephemerides in :mod:`tollcli.gnss.lnav_subframes`;
* ``NAV-PVT``: the receiver's own solution (time, position, ground speed, accuracies), for comparison.

Messages that fail their checksum or cannot be parsed are skipped and counted (NMEA and RTCM
between the UBX frames are not errors: they are another protocol on the same port).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError
from tollcli.times import plausible_date

UBX_SYNC = b"\xb5\x62"
#: UBX gnssId → constellation name
GNSS_ID = {0: "GPS", 1: "SBAS", 2: "Galileo", 3: "BeiDou", 5: "QZSS", 6: "GLONASS", 7: "NavIC"}
_NAME_TO_ID = {"GPS": 0, "SBAS": 1, "GALILEO": 2, "Galileo": 2, "BEIDOU": 3, "BeiDou": 3, "QZSS": 5, "GLONASS": 6,
               "NAVIC": 7, "NavIC": 7, "IMES": 4}  # fmt: skip
RAWX_COLUMNS = ("rcvTow", "week", "leapS", "prMes", "cpMes", "doMes", "gnssId", "svId", "sigId", "freqId", "locktime",
                "cno", "prStd", "cpStd", "doStd", "prValid", "cpValid")  # fmt: skip


#: RAWX rows gathered as tuples before they are made a table (then the next block): the memory of a long log's
#: measurements is its table's, not its Python tuples' (28.7 MB at the peak on a 536-epoch walk of 37 850 measurements,
#: a 5.5 MB table)
RAWX_BLOCK_ROWS = 5_000


@dataclass
class UbxRead:
    rawx: pd.DataFrame  # one row per RXM-RAWX measurement (RAWX_COLUMNS + ``message``)
    sfrbx: pd.DataFrame  # one row per RXM-SFRBX: gnssId, svId, sigId, words (10 × uint32), message
    pvt: pd.DataFrame  # one row per NAV-PVT
    n_messages: int
    n_bad: int  # UBX frames that failed their checksum or could not be parsed


def is_ubx(head: bytes) -> bool:
    """Whether the first bytes of a file hold a UBX frame (sync chars followed by a known class)."""
    at = head.find(UBX_SYNC)
    return at >= 0 and at + 2 < len(head) and head[at + 2] in (0x01, 0x02, 0x05, 0x06, 0x0A, 0x0D, 0x10, 0x13, 0x21, 0x27, 0x28)


def _int_id(value) -> int:
    if isinstance(value, (int, np.integer)):
        return int(value)
    return _NAME_TO_ID.get(str(value), -1)


def read_ubx(path: str, strict: bool = False) -> UbxRead:
    """The RAWX, SFRBX and PVT messages of a UBX (or mixed UBX/NMEA/RTCM) log."""
    try:
        from pyubx2 import UBX_PROTOCOL, UBXReader
    except ImportError:  # pragma: no cover - a dependency of the package
        raise UsageError("reading UBX needs pyubx2 (pip install pyubx2)") from None
    errors: list[str] = []
    rawx: list[tuple] = []
    rawx_blocks: list[pd.DataFrame] = []
    sfrbx: list[tuple] = []
    pvt: list[tuple] = []
    n = 0
    try:
        stream = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot open ({exc.strerror})") from None
    with stream:
        reader = UBXReader(stream, protfilter=UBX_PROTOCOL, quitonerror=1, errorhandler=lambda e: errors.append(str(e)))
        while True:
            try:
                raw, msg = reader.read()
            except Exception as exc:  # pyubx2 raises its own kinds on a damaged frame; skip it, counted
                errors.append(f"{type(exc).__name__}: {exc}")
                if strict:
                    break
                continue
            if raw is None:
                break
            if msg is None:
                continue
            n += 1
            ident = msg.identity
            if ident == "RXM-RAWX":
                base = (msg.rcvTow, msg.week, msg.leapS)
                for k in range(1, int(msg.numMeas) + 1):
                    s = f"_{k:02d}"
                    rawx.append((*base, *(getattr(msg, c + s, np.nan) for c in RAWX_COLUMNS[3:]), n))
                if len(rawx) >= RAWX_BLOCK_ROWS:  # a block of rows as columns: a tuple of Python numbers is 4× their size
                    rawx_blocks.append(pd.DataFrame(rawx, columns=[*RAWX_COLUMNS, "message"]))
                    rawx = []
            elif ident == "RXM-SFRBX":
                words = tuple(int(getattr(msg, f"dwrd_{k:02d}", 0)) for k in range(1, int(msg.numWords) + 1))
                sfrbx.append((_int_id(msg.gnssId), int(msg.svId), _int_id(getattr(msg, "sigId", 0)), words, n))
            elif ident == "NAV-PVT":
                pvt.append((msg.year, msg.month, msg.day, msg.hour, msg.min, msg.second, msg.nano, msg.fixType,
                            msg.lat, msg.lon, msg.height / 1000.0, msg.gSpeed / 1000.0, msg.hAcc / 1000.0,
                            msg.sAcc / 1000.0, msg.numSV, n))  # fmt: skip
    if strict and errors:
        raise DataError(f"{path}: UBX message {n + 1}: {errors[0]}")
    if n == 0 and not rawx:
        raise DataError(f"{path}: no UBX messages")
    raw_table = pd.DataFrame(rawx, columns=[*RAWX_COLUMNS, "message"])
    if rawx_blocks:
        raw_table = pd.concat([*rawx_blocks, raw_table], ignore_index=True)
    for name in ("gnssId", "sigId"):
        raw_table[name] = [_int_id(v) for v in raw_table[name]]
    sf = pd.DataFrame(sfrbx, columns=["gnssId", "svId", "sigId", "words", "message"])
    pvt_table = pd.DataFrame(pvt, columns=["year", "month", "day", "hour", "minute", "second", "nano", "fix_type", "lat_deg",
                                           "lon_deg", "height_m", "speed_mps", "h_acc_m", "speed_acc_mps", "n_sv", "message"])  # fmt: skip
    dated = plausible_date(*(pvt_table[c].to_numpy(np.int64) for c in ("year", "month", "day", "hour", "minute", "second")))
    if not dated.all():  # a damaged date (year 60000) is no date: the row is dropped, and counted
        if strict:
            raise DataError(f"{path}: UBX message {int(pvt_table['message'][~dated].iloc[0]) + 1}: NAV-PVT with an impossible date")
        errors += ["NAV-PVT with an impossible date"] * int((~dated).sum())
        pvt_table = pvt_table[dated].reset_index(drop=True)
    return UbxRead(raw_table, sf, pvt_table, n, len(errors))
