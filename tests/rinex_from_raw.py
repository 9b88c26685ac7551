"""Test helper: a RINEX 3 observation file (GPS L1 C/A pseudoranges, C/N0) from a phone's raw measurements.

RTKLIB reads RINEX, not Android's raw records: this lets the tests run Debian's ``rnx2rtkp`` on a real phone's
measurements (``../shared/data/gsdc2022/device_gnss.csv`` with that day's ``brdc1190.21n``).
"""

from __future__ import annotations

import numpy as np

from tollcli.gnss.android_raw import raw_pseudoranges
from tollcli.readers.gnsslogger import read_device_gnss, read_gnsslogger


def _header_line(text: str, label: str) -> str:
    return f"{text:<60}{label}\n"


def write_rinex_obs(raw_path: str, out_path: str) -> int:
    """Write the GPS L1 C/A pseudoranges of a GnssLogger file or a GSDC device_gnss.csv as RINEX 3.03; the epochs."""
    raw = read_device_gnss(raw_path) if raw_path.endswith(".csv") else read_gnsslogger(raw_path).raw
    pr = raw_pseudoranges(raw)
    pr = pr[pr["pr_valid"] & (pr["constellation"] == "GPS") & (pr["signal"] == "L1") & np.isfinite(pr["t_rx_gps_s"])]
    epochs = sorted(pr.groupby("epoch_key"), key=lambda kv: float(kv[1]["t_rx_gps_s"].iloc[0]))
    gps0 = np.datetime64("1980-01-06T00:00:00", "ns")

    def stamp(t_s: float) -> tuple:
        t = gps0 + np.timedelta64(int(round(t_s * 1e9)), "ns")
        day = str(t.astype("datetime64[D]"))
        sec = (t - t.astype("datetime64[D]")).astype(np.int64) / 1e9
        h, rem = divmod(sec, 3600)
        m, s = divmod(rem, 60)
        y, mo, d = (int(x) for x in day.split("-"))
        return y, mo, d, int(h), int(m), s

    lines = [_header_line("     3.03           OBSERVATION DATA    G (GPS)", "RINEX VERSION / TYPE"),
             _header_line("tollcli tests", "PGM / RUN BY / DATE"),
             _header_line("PIXEL4", "MARKER NAME"),
             _header_line("        0.0000        0.0000        0.0000", "APPROX POSITION XYZ"),
             _header_line("        0.0000        0.0000        0.0000", "ANTENNA: DELTA H/E/N"),
             _header_line("G    2 C1C S1C", "SYS / # / OBS TYPES")]
    y, mo, d, h, m, s = stamp(float(epochs[0][1]["t_rx_gps_s"].iloc[0]))
    lines.append(_header_line(f"  {y:4d}    {mo:2d}    {d:2d}    {h:2d}    {m:2d}   {s:10.7f}     GPS", "TIME OF FIRST OBS"))
    lines.append(_header_line("", "END OF HEADER"))
    for _, rows in epochs:
        rows = rows.drop_duplicates("svid").sort_values("svid")
        y, mo, d, h, m, s = stamp(float(rows["t_rx_gps_s"].iloc[0]))
        lines.append(f"> {y:4d} {mo:02d} {d:02d} {h:02d} {m:02d}{s:11.7f}  0{len(rows):3d}\n")
        for svid, pr_m, cn0 in zip(rows["svid"], rows["pr_m"], rows["cn0_dbhz"]):
            lines.append(f"G{int(svid):02d}{pr_m:14.3f}  {cn0:14.3f}  \n")
    with open(out_path, "w", encoding="ascii") as fh:
        fh.writelines(lines)
    return len(epochs)
