"""Test helper: RINEX 3.04 navigation and observation files from a real u-blox log's own data.

The navigation records are the ephemerides tollcli decoded from the log's ``RXM-SFRBX`` (GPS LNAV, Galileo I/NAV,
BeiDou D1, GLONASS strings), written in each system's RINEX 3 layout and time (GPS and Galileo in GPS time, BeiDou
in BDT, GLONASS in UTC with its state in km); the observations are the log's ``RXM-RAWX`` code pseudoranges (GPS
C1C, Galileo C1C, BeiDou C6I and C2I, GLONASS C1C) with their C/N0. Reading them back through the RINEX path must
give what the u-blox path gives from the same bytes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.gnss.beidou_d1 import BDT_GPS_S, BDT_WEEK_OFFSET
from tollcli.gnss.orbits import WEEK_S
from tollcli.readers.gps_time import leap_seconds_at_gps

GPS0 = np.datetime64("1980-01-06T00:00:00", "ns")


def _d(v) -> str:
    v = 0.0 if v is None or not np.isfinite(v) else float(v)
    return f"{v:19.12E}".replace("E", "D")


def _stamp(t_s: float) -> str:
    ts = pd.Timestamp(GPS0 + np.timedelta64(int(round(t_s * 1e9)), "ns"))
    return f"{ts.year:4d} {ts.month:02d} {ts.day:02d} {ts.hour:02d} {ts.minute:02d} {ts.second:02d}"


def write_nav(path, eph: pd.DataFrame) -> None:
    """Every ephemeris of a tollcli ephemeris table as a RINEX 3.04 mixed navigation file."""
    head = [f"{'3.04':>9}{'':11}{'N: GNSS NAV DATA':<20}{'M: MIXED':<20}RINEX VERSION / TYPE", f"{'':60}END OF HEADER"]
    body = []
    for _, e in eph.iterrows():
        sv, system = e["sv"], e["sv"][0]
        g = lambda name: e[name] if name in e and pd.notna(e[name]) else 0.0  # noqa: E731
        if system == "R":
            epoch = e["toc_s"] - float(leap_seconds_at_gps(np.array([e["toc_s"]]))[0])  # UTC
            body.append(f"{sv} {_stamp(epoch)}" + _d(g("SVclockBias")) + _d(g("SVrelFreqBias")) + _d(0.0))
            for axis in ("X", "Y", "Z"):
                last = g("health") if axis == "X" else (g("FreqNum") if axis == "Y" else 0.0)
                body.append("    " + _d(g(axis) / 1e3) + _d(g("d" + axis) / 1e3) + _d(g("d" + axis + "2") / 1e3) + _d(last))
            continue
        beidou = system == "C"
        shift = BDT_GPS_S if beidou else 0.0
        week = np.floor((e["toe_s"] - shift) / WEEK_S) - (BDT_WEEK_OFFSET if beidou else 0)
        toe = np.mod(e["toe_s"] - shift, WEEK_S)
        body.append(f"{sv} {_stamp(e['toc_s'] - shift)}" + _d(g("SVclockBias")) + _d(g("SVclockDrift")) + _d(g("SVclockDriftRate")))
        lines = [
            (g("iode"), g("Crs"), g("DeltaN"), g("M0")),
            (g("Cuc"), g("Eccentricity"), g("Cus"), g("sqrtA")),
            (toe, g("Cic"), g("Omega0"), g("Cis")),
            (g("Io"), g("Crc"), g("omega"), g("OmegaDot")),
            (g("IDOT"), 517.0 if system == "E" else 0.0, week, 0.0),
        ]
        if beidou:
            lines += [(0.0, g("health"), g("TGD1"), g("TGD2")), (toe, 0.0)]
        elif system == "E":
            lines += [(3.12, g("health"), g("BGDe5a"), g("BGDe5b")), (toe, 0.0)]
        else:
            lines += [(2.0, g("health"), g("TGD"), g("iode")), (toe, 4.0)]
        body += ["    " + "".join(_d(v) for v in line) for line in lines]
    path.write_text("\n".join(head + body) + "\n")


#: (system letter, u-blox signal) → RINEX 3 observation code
CODES = {("G", "L1"): "C1C", ("E", "E1"): "C1C", ("C", "B3I"): "C6I", ("C", "B1I"): "C2I", ("R", "G1"): "C1C"}


def write_obs(path, rawx: pd.DataFrame) -> int:
    """The code pseudoranges of ``rawx`` (tollcli's ``rawx_measurements``) as a RINEX 3.04 observation file (one code
    per system: :data:`CODES`); the epochs written."""
    m = rawx[rawx["pr_valid"]].copy()
    m["sys"] = m["sv"].str[0]
    m["code"] = [CODES.get((s, sig)) for s, sig in zip(m["sys"], m["signal"])]
    m = m[m["code"].notna()]
    codes = {s: sorted(set(m.loc[m["sys"] == s, "code"])) for s in sorted(set(m["sys"]))}
    head = [f"{'3.04':>9}{'':11}{'OBSERVATION DATA':<20}{'M':<20}RINEX VERSION / TYPE",
            f"{'WALK':<60}MARKER NAME", f"{'        0.0000        0.0000        0.0000':<60}APPROX POSITION XYZ"]  # fmt: skip
    for s, cs in codes.items():
        types = [x for c in cs for x in (c, "S" + c[1:])]
        text = f"{s}  {len(types):3d} " + " ".join(f"{t:3s}" for t in types)
        head.append(f"{text:<60}SYS / # / OBS TYPES")
    first = pd.Timestamp(GPS0 + np.timedelta64(int(round(m["t_rx_gps_s"].min() * 1e9)), "ns"))
    stamp = f"{first.year:6d}{first.month:6d}{first.day:6d}{first.hour:6d}{first.minute:6d}{first.second:13.7f}{'':5}GPS"
    head += [f"{stamp:<60}TIME OF FIRST OBS", f"{'':60}END OF HEADER"]
    body = []
    n = 0
    for t, group in m.groupby("t_rx_gps_s", sort=True):
        rows = []
        for sv, sat in group.groupby("sv", sort=True):
            cs = codes[sv[0]]
            values = []
            for c in cs:
                pick = sat[sat["code"] == c]
                pr = pick["pr_m"].iloc[0] if len(pick) else np.nan
                cn0 = pick["cn0_dbhz"].iloc[0] if len(pick) else np.nan
                values += [pr, cn0]
            rows.append(sv + "".join(f"{v:14.3f}  " if np.isfinite(v) else " " * 16 for v in values))
        ts = pd.Timestamp(GPS0 + np.timedelta64(int(round(t * 1e9)), "ns"))
        seconds = ts.second + ts.microsecond / 1e6 + ts.nanosecond / 1e9
        body.append(f"> {ts.year:4d} {ts.month:02d} {ts.day:02d} {ts.hour:02d} {ts.minute:02d}{seconds:11.7f}  0{len(rows):3d}")
        body += rows
        n += 1
    path.write_text("\n".join(head + body) + "\n")
    return n
