"""What a pseudorange log costs `tollcli integrity` as it grows: seconds and peak memory on the first quarter of a long
simulated city drive, on the whole of it, and on a drive twice as long, in the same run.

    python benchmarks/pseudorange_memory.py [--epochs 40000] [--longer 80000]

The drive is ``tollcli simulate --nlos --odometry --duration 8000 --rate 5 --seed 11`` (40 000 epochs at 5 Hz, written
once into ``benchmarks/integrity_truth/sim/city-long``, ≈ 80 s), as libRSF text (pseudoranges and odometry) and as a
GSDC derived CSV, and the derived CSV's measurements as a GSDC ``device_gnss.csv`` (:func:`device_gnss`); the longer
one the same with ``--duration 16000`` (``sim/city-80000``, ≈ 3 min once). Then RINEX 3 and RINEX 2 observations of a
static receiver at 10 Hz (:func:`rinex_drive`, ``sim/rinex-static``; ``--rinex-only``: only those) of a quarter, the whole
and the longer number of epochs. Each is cut to its first quarter (whole lines, the same epochs) and run with the whole and the longer drive. The ratios of the
peak RSS say how memory grows with the log (4.0 whole / quarter: in proportion; 1.0: flat). Every format is read in
blocks and placed segment by segment (``tollcli/job/pseudorange_segments.py``: cores of 8 192 epochs and at least
30 min, each with 1 024 epochs of margin), so beyond a segment and a half the memory stays a segment's.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from process_throughput import timed  # noqa: E402  (benchmarks/ is on sys.path)
from trajectory_cost import LONG, simulated_drive  # noqa: E402


def quarter(path: Path, out: Path, header: bool, epochs: int) -> None:
    """The lines of ``path`` whose epoch is among its first ``epochs`` (libRSF: time stamp below; CSV: the first
    ``epochs`` distinct epoch keys)."""
    seen: list[str] = []
    with open(path) as src, open(out, "w") as dst:
        if header:
            columns = src.readline()
            dst.write(columns)
            key = columns.strip().split(",").index("millisSinceGpsEpoch")
        for line in src:
            fields = line.split(",") if header else line.split()
            stamp = fields[key] if header else fields[1]
            if not seen or seen[-1] != stamp:
                if len(seen) == epochs:
                    break
                seen.append(stamp)
            dst.write(line)


#: Android's constellation types, carriers and tracking states of a decoded time of week (code lock, TOW decoded;
#: Galileo also E1BC code lock), for the simulator's GPS L1 and Galileo E1
ANDROID = {1: (1_575_420_000.0, 1 | 8), 6: (1_575_420_000.0, 1 | 8 | 1024)}


def device_gnss(derived: Path, out: Path, chunk_rows: int = 200_000) -> None:
    """The derived CSV's measurements as a GSDC ``device_gnss.csv``: the pseudorange as Android states it (receiver time
    TimeNanos − FullBiasNanos, transmit time ReceivedSvTimeNanos, the sub-nanosecond rest in TimeOffsetNanos) and the
    satellites, clocks and delays in Google's columns (so no ``--nav``)."""
    import numpy as np
    import pandas as pd

    c, week_ns = 299_792_458.0, 604_800 * 10**9
    header = True
    with open(out, "w") as dst:
        for d in pd.read_csv(derived, chunksize=chunk_rows):
            millis = d["millisSinceGpsEpoch"].to_numpy(np.int64)
            time_nanos = (millis - 1_400_000_000_000) * 10**6  # the phone's hardware clock: its own zero
            flight = d["rawPrM"].to_numpy(float) / c * 1e9
            whole = np.floor(flight).astype(np.int64)
            carrier, state = (np.array([ANDROID[k][i] for k in d["constellationType"].tolist()]) for i in (0, 1))
            table = pd.DataFrame({
                "TimeNanos": time_nanos, "FullBiasNanos": time_nanos - millis * 10**6, "BiasNanos": 0.0, "TimeOffsetNanos": flight - whole,
                "ReceivedSvTimeNanos": (millis * 10**6) % week_ns - whole, "ReceivedSvTimeUncertaintyNanos": d["rawPrUncM"] / c * 1e9,
                "State": state, "Svid": d["svid"], "ConstellationType": d["constellationType"], "Cn0DbHz": 40.0,
                "PseudorangeRateMetersPerSecond": np.nan, "CarrierFrequencyHz": carrier,
                "SvPositionXEcefMeters": d["xSatPosM"], "SvPositionYEcefMeters": d["ySatPosM"], "SvPositionZEcefMeters": d["zSatPosM"],
                "SvVelocityXEcefMetersPerSecond": d["xSatVelMps"], "SvVelocityYEcefMetersPerSecond": d["ySatVelMps"],
                "SvVelocityZEcefMetersPerSecond": d["zSatVelMps"], "SvClockBiasMeters": d["satClkBiasM"],
                "SvClockDriftMetersPerSecond": d["satClkDriftMps"], "IsrbMeters": d["isrbM"], "IonosphericDelayMeters": d["ionoDelayM"],
                "TroposphericDelayMeters": d["tropoDelayM"]})  # fmt: skip
            table.to_csv(dst, index=False, header=header)
            header = False


def rinex_drive(folder: Path, epochs: int, rate_hz: int = 10, version: int = 3) -> tuple[Path, Path]:
    """A static receiver's RINEX 3.04 (``version`` 2: 2.11) observations (GPS and Galileo, ``rate_hz``) and navigation
    file, from the test suite's simulator (``tests/rinex_synth.py``: light-time pseudoranges, Klobuchar, Saastamoinen):
    each second simulated, the epochs between interpolated linearly (a range's curvature over a second: millimetres).
    Written once."""
    import datetime as dt

    sys.path.insert(0, str(ROOT / "tests"))
    from rinex_synth import constellation, observe, write_nav

    obs, nav = folder / f"static{'' if version == 3 else version}-{epochs}.24o", folder / "static.24n"
    if obs.exists() and nav.exists():
        return obs, nav
    folder.mkdir(parents=True, exist_ok=True)
    start = dt.datetime(2024, 5, 6, 8, 0, 0)
    sats = constellation(start)
    write_nav(nav, sats)
    seconds = -(-epochs // rate_hz) + 1
    rows = observe(sats, start, seconds, 42.6987, 2.8956, 60.0, noise_m=1.0, seed=2)
    by_second: dict[int, dict[str, tuple[float, float]]] = {}
    for k, sv, pr, cn0 in rows:
        by_second.setdefault(k, {})[sv] = (pr, cn0)
    head = [f"{'3.04':>9}{'':11}{'OBSERVATION DATA':<20}{'M':<20}RINEX VERSION / TYPE", f"{'G    2 C1C S1C':<60}SYS / # / OBS TYPES",
            f"{'E    2 C1C S1C':<60}SYS / # / OBS TYPES",
            f"{start.year:6d}{start.month:6d}{start.day:6d}{start.hour:6d}{start.minute:6d}{start.second:13.7f}     GPS         TIME OF FIRST OBS",
            f"{'':60}END OF HEADER"]  # fmt: skip
    if version == 2:
        head = [f"{'2.11':>9}{'':11}{'OBSERVATION DATA':<20}{'M (MIXED)':<20}RINEX VERSION / TYPE", f"{'     2    C1    S1':<60}# / TYPES OF OBSERV",
                head[3], head[4]]  # fmt: skip
    with open(obs, "w") as out:
        out.write("\n".join(head) + "\n")
        for e in range(epochs):
            k, f = divmod(e, rate_hz)
            now, then = by_second.get(k, {}), by_second.get(k + 1, {})
            both = sorted(set(now) & set(then))
            t = start + dt.timedelta(seconds=e / rate_hz)
            if version == 2:
                svs = "".join(both)
                lines = [f" {t:%y} {t.month:2d} {t.day:2d} {t.hour:2d} {t.minute:2d}{t.second + t.microsecond / 1e6:11.7f}  0{len(both):3d}{svs[:36]}"]
                lines += [f"{'':32}{svs[i : i + 36]}" for i in range(36, len(svs), 36)]
            else:
                lines = [f"> {t:%Y %m %d %H %M}{t.second + t.microsecond / 1e6:11.7f}  0{len(both):3d}"]
            for sv in both:
                pr = now[sv][0] + (then[sv][0] - now[sv][0]) * f / rate_hz
                lines.append(f"{sv if version == 3 else ''}{pr:14.3f}  {now[sv][1]:14.3f}  ")
            out.write("\n".join(lines) + "\n")
    return obs, nav


def rinex_memory(quarter_epochs: int, epochs: int, longer: int) -> None:
    """``integrity`` of the static receiver's RINEX files of ``quarter_epochs``, ``epochs`` and ``longer`` epochs."""
    folder = Path(os.path.dirname(LONG)) / "rinex-static"
    tollcli = [sys.executable, "-m", "tollcli", "integrity"]
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for version in (3, 2):
            for n in (quarter_epochs, epochs, longer):
                obs, nav = rinex_drive(folder, n, version=version)
                runs[n] = timed([*tollcli, str(obs), "--nav", str(nav), "-q", "-o", str(Path(tmp) / "table.csv")])
                print(f"  RINEX {version} (10 Hz)  {n // 1000:3d}k epochs {obs.stat().st_size / 1e6:5.0f} MB: {runs[n][0]:6.2f} s, "
                      f"peak RSS {runs[n][1]:6.0f} MB")  # fmt: skip
            print(f"  RINEX {version}          {epochs // 1000}k / {quarter_epochs // 1000}k: peak RSS {runs[epochs][1] / runs[quarter_epochs][1]:.2f}; "
                  f"{longer // 1000}k / {epochs // 1000}k: {runs[longer][1] / runs[epochs][1]:.2f}")  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=40_000, help="the whole drive's epochs (5 Hz)")
    parser.add_argument("--longer", type=int, default=80_000, help="a longer drive's epochs (0: none)")
    parser.add_argument("--rinex-only", action="store_true", help="only the RINEX files (3 and 2: a static receiver at 10 Hz)")
    args = parser.parse_args()
    if args.rinex_only:
        rinex_memory(args.epochs // 4, args.epochs, args.longer or 2 * args.epochs)
        return 0
    folder = LONG if args.epochs == 40_000 else os.path.join(os.path.dirname(LONG), f"city-{args.epochs}")
    librsf = Path(simulated_drive(folder, args.epochs // 5))
    derived = librsf.with_name("drive-derived.csv")
    tollcli = [sys.executable, "-m", "tollcli", "integrity"]
    print(f"a simulated city drive of {args.epochs} epochs (5 Hz); tollcli integrity, wall time and peak RSS")
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, header in (("libRSF", librsf, False), ("GSDC derived CSV", derived, True), ("device_gnss.csv", derived, True)):
            part = Path(tmp) / f"quarter{path.suffix}"
            quarter(path, part, header, args.epochs // 4)
            if name == "device_gnss.csv":  # (the derived CSV's measurements, whole and the quarter, as Android gives them)
                for src, dst in ((part, part), (path, Path(tmp) / "device_gnss.csv")):
                    device_gnss(src, Path(tmp) / "converting.csv")
                    os.replace(Path(tmp) / "converting.csv", dst)
                path = Path(tmp) / "device_gnss.csv"
            runs = {}
            for label, log in (("quarter", part), ("whole", path)):
                runs[label] = timed([*tollcli, str(log), "-q", "-o", str(Path(tmp) / "table.csv")])
                print(f"  {name:16s} {label:7s} {log.stat().st_size / 1e6:5.0f} MB: {runs[label][0]:6.2f} s, peak RSS {runs[label][1]:6.0f} MB")
            print(f"  {name:16s} whole / quarter: time {runs['whole'][0] / runs['quarter'][0]:.2f}, peak RSS "
                  f"{runs['whole'][1] / runs['quarter'][1]:.2f}")  # fmt: skip
            if args.longer:
                longer = Path(simulated_drive(os.path.join(os.path.dirname(LONG), f"city-{args.longer}"), args.longer // 5))
                longer = longer.with_name(path.name if name != "device_gnss.csv" else derived.name)  # (the simulator writes both)
                if name == "device_gnss.csv":
                    device_gnss(longer, Path(tmp) / "longer.csv")
                    longer = Path(tmp) / "longer.csv"
                runs["longer"] = timed([*tollcli, str(longer), "-q", "-o", str(Path(tmp) / "table.csv")])
                print(f"  {name:16s} {args.longer // 1000}k epochs {longer.stat().st_size / 1e6:5.0f} MB: {runs['longer'][0]:6.2f} s, "
                      f"peak RSS {runs['longer'][1]:6.0f} MB; {args.longer // 1000}k / {args.epochs // 1000}k: time "
                      f"{runs['longer'][0] / runs['whole'][0]:.2f}, peak RSS {runs['longer'][1] / runs['whole'][1]:.2f}")  # fmt: skip
    rinex_memory(args.epochs // 4, args.epochs, args.longer or 2 * args.epochs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
