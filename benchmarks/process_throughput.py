"""``tollcli process`` on a 10-hour 1 Hz drive through a network of 10 000 geo-objects.

The drive: ``compose.straight_drive`` (GPS+Galileo, 9 sentences per epoch, 13.9 m/s), 36 000
epochs. The network: the motorway under the drive cut into 250 m tolled segments,
plus parallel tolled roads 300 m apart, all cut the same way, to 10 000
geo-objects (built by ``build_geoobjects``; HAL 50 m). Reported, each in a fresh
process: wall time and peak RSS of ``tollcli process``, and of ``tollcli epochs``
(the reader alone, the baseline; best of 3, and its lines per second) on the same log. ``process`` runs twice: first
with an empty cache directory (it parses the geo-object GeoJSON and compiles it),
then again (it reads the compiled copy: what every later log of a fleet sees; best of 3), and on one thread
(``TOLLCLI_READ_AHEAD=0``: the next chunk not read while this one is checked; best of 2). The commands run as an
installed package does, with tollcli's bytecode compiled (``compileall`` first; the environment
variable ``PYTHONDONTWRITEBYTECODE`` is dropped for them).
``--mix ublox``: a 25 m/s drive written with the sentences of a real u-blox ZED-F9P (``ublox-zed-f9p-nmea.log``
of ``../shared/data/gpsd/``, epoch by epoch, as :func:`real_patterns.drive` replays it): RMC VTG GGA 4×GSA
24×GSV GLL GST ZDA GBS, its GST with an RMS field that is no range RMS (10⁵ "m") and 2.3/3.5/4.0 m σ's, its
GBS (the receiver's RAIM, no failed satellite), no GRS; the share of the segments under the track that are
charged, the parallel roads (300 m apart) charged, the findings, and the time ``pynmea2.parse`` alone needs
for the file are printed beside; then ``--pairs`` (3) ratios of a warm ``process`` to ``pynmea2.parse`` timed right
after it, and their median (the two seconds apart, not minutes: a shared machine's speed drifts), and as many of
``tollcli epochs`` to ``pynmea2.parse``.
``--mix neo-m9n``: the same drive without the ZED-F9P's second-band GSV lines (:func:`real_patterns.first_band`: 12 GSV lines an
epoch instead of 24, 23 lines an epoch, 828 000 lines in 10 h — what a single-band u-blox NEO-M9N with GST, GBS and ZDA
on writes, and the line count of the 10 h drive issue 49 was measured on).
``--mix satellites-only``: the same 25 m/s drive with the sentences of a real SiRF IV receiver that writes GGA RMC GSA
GSV only (``bu353s4.log``): the ``model`` level; with ``--environment open`` (open country declared) it is charged, and
so it is with ``--declare open`` (the geo-objects built with ``geoobjects build --environment motorway=open``: the
operator declares the motorways open, process runs with its defaults); ``--declare urban``: nothing is charged.
``--mix ubx``: the drive as u-blox NAV-SAT (with prRes) + NAV-PVT frames replayed from the real OSNMA recording
(``../shared/data/osnma/ublox/current_config.ubx``); ``--bias-m 60`` adds 60 m to one used satellite's prRes for 60
epochs mid-drive and prints the verdicts there (the residual test must flag them).
``--memory-hours 1 10 100`` adds the peak RSS of ``process`` over those drive
lengths (same network), with the ratio of the longest to the shortest.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import tollcli as tollcli_package
from tollcli.geoobjects.build import build_geoobjects
from tollcli.readers.nmea.compose import straight_drive

from reader_throughput import plain_pynmea2  # noqa: E402  the same baseline as the reader's benchmark (benchmarks/ is on sys.path)

START = (42.6987, 2.8956)
COURSE = math.radians(45.0)
SPEED = 13.9  # compose.straight_drive's
UBLOX_SPEED = 25.0
PARALLEL_M = 300.0  # between neighbouring parallel roads


def point(s_m: float, offset_m: float) -> list[float]:
    north = s_m * math.cos(COURSE) + offset_m * math.cos(COURSE - math.pi / 2)
    east = s_m * math.sin(COURSE) + offset_m * math.sin(COURSE - math.pi / 2)
    lat = START[0] + north / 111_132.0
    return [START[1] + east / (111_320.0 * math.cos(math.radians(START[0]))), lat]


def roads(n_objects: int, length_m: float, seg_m: float = 250.0) -> dict:
    """The road under the drive (R0) and parallel roads ``PARALLEL_M`` apart, cut into ``seg_m`` segments."""
    per_road = int(length_m // seg_m)
    n_roads = math.ceil(n_objects / per_road)
    feats = []
    for r in range(n_roads):
        offset = PARALLEL_M * ((r + 1) // 2) * (1 if r % 2 else -1)
        for k in range(per_road):
            if len(feats) == n_objects:
                break
            feats.append({"type": "Feature", "properties": {"id": f"R{r}-{k}", "road_class": "motorway"},
                          "geometry": {"type": "LineString", "coordinates": [point(k * seg_m, offset), point((k + 1) * seg_m, offset)]}})  # fmt: skip
    return {"type": "FeatureCollection", "features": feats}


UBLOX_LOG = "ublox-zed-f9p-nmea.log"  # the real u-blox pattern (GST with a 10⁵ "m" RMS field, GBS, ZDA, no GRS)
SATELLITES_ONLY_LOG = "bu353s4.log"  # a real SiRF IV receiver writing GGA RMC GSA GSV only: the model level
UBX_LOG = Path(__file__).resolve().parents[2] / "shared" / "data" / "osnma" / "ublox" / "current_config.ubx"  # NAV-PVT + NAV-SAT


def _track(k: int):
    """Epoch k of the 25 m/s drive: its position on the road under the track, and the speed and course its positions
    show (the flat road map stretches east-west by cos(latitude) over 900 km: the speed over ground follows it, so a
    receiver's Doppler speed and its positions agree, as a real receiver's do)."""
    from tollcli.geodesy import great_circle_distance_m

    lon, lat = point(k * UBLOX_SPEED, 0.0)
    lon1, lat1 = point((k + 1) * UBLOX_SPEED, 0.0)
    speed = float(great_circle_distance_m(lat, lon, lat1, lon1))
    y = math.sin(math.radians(lon1 - lon)) * math.cos(math.radians(lat1))
    x = math.cos(math.radians(lat)) * math.sin(math.radians(lat1)) - math.sin(math.radians(lat)) * math.cos(
        math.radians(lat1)) * math.cos(math.radians(lon1 - lon))  # fmt: skip
    return lat, lon, speed, math.degrees(math.atan2(y, x)) % 360.0


def satellites_only_drive(path: Path, n_epochs: int) -> None:
    """A drive with the real GSA+GSV-only receiver's sentences (bu353s4.log), epoch by epoch."""
    import real_patterns

    real_patterns.drive(real_patterns.DATA / SATELLITES_ONLY_LOG, path, n_epochs, _track)


def ubx_nav_drive(path: Path, n_epochs: int, bias: tuple[int, int, float] | None = None) -> None:
    """A drive replaying the real u-blox recording's NAV-SAT (with prRes) and NAV-PVT, epoch by epoch."""
    import real_patterns

    real_patterns.ubx_drive(UBX_LOG, path, n_epochs, _track, bias=bias)


def ublox_drive(path: Path, n_epochs: int, single_band: bool = False) -> None:
    """A drive along the motorway at ``UBLOX_SPEED`` with the real u-blox log's sentences, epoch by epoch (``single_band``:
    without its second band's GSV lines)."""
    import real_patterns

    def track(k: int):
        lon, lat = point(k * UBLOX_SPEED, 0.0)
        return lat, lon, UBLOX_SPEED, math.degrees(COURSE)

    real_patterns.drive(real_patterns.DATA / UBLOX_LOG, path, n_epochs, track, single_band=single_band)


def paired_ratios(process: list[str], env: dict, log: Path, pairs: int) -> list[float]:
    """``pairs`` ratios of a command (a warm ``process``, ``epochs``) to ``pynmea2.parse`` of ``log`` timed right after it: the two measured
    within seconds of each other, so a machine whose speed drifts over minutes (a shared host) moves both alike."""
    ratios = []
    for _ in range(pairs):
        t_proc, _ = timed(process, env)
        ratios.append(t_proc / plain_pynmea2(log))
    return ratios


def timed(cmd: list[str], env: dict | None = None) -> tuple[float, float]:
    """Wall time (s) and peak RSS (MB) of a command in a fresh process."""
    code = ("import resource, subprocess, sys, time\n"
            "t = time.perf_counter(); subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL)\n"
            "print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code, *cmd], capture_output=True, text=True, check=True, env=env).stdout.split()
    return float(out[0]), int(out[1]) / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=10.0)
    parser.add_argument("--objects", type=int, default=10_000)
    parser.add_argument("--memory-hours", type=float, nargs="*", default=[], help="drive lengths for the memory test, h")
    parser.add_argument("--mix", choices=("compose", "ublox", "neo-m9n", "satellites-only", "ubx"), default="compose",
                        help="the drive's sentence mix: compose, ublox (ZED-F9P NMEA), neo-m9n (the same, single band), "
                        "satellites-only (bu353s4 GSA+GSV), "
                        "ubx (the OSNMA recording's NAV-PVT + NAV-SAT)")  # fmt: skip
    parser.add_argument("--environment", default="auto", help="tollcli's --environment (satellites-only: open declares open country)")
    parser.add_argument("--declare", choices=("open", "urban"), default=None,
                        help="build the geo-objects with the motorways declared open or urban (geoobjects build --environment motorway=...)")
    parser.add_argument("--pairs", type=int, default=3, help="warm process / pynmea2.parse ratios timed back to back (0: none)")
    parser.add_argument("--bias-m", type=float, default=0.0, help="ubx mix: add this to one used satellite's prRes for 60 s mid-drive")
    args = parser.parse_args()
    n_epochs = int(args.hours * 3600)
    tollcli = [sys.executable, "-m", "tollcli"]
    tariff = Path(__file__).resolve().parents[1] / "geoobjects" / "example-tariff.toml"
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / ("drive.ubx" if args.mix == "ubx" else "drive.nmea")
        speed = SPEED if args.mix == "compose" else UBLOX_SPEED
        if args.mix in ("ublox", "neo-m9n"):
            ublox_drive(log, n_epochs, single_band=args.mix == "neo-m9n")
        elif args.mix == "satellites-only":
            satellites_only_drive(log, n_epochs)
        elif args.mix == "ubx":
            mid = n_epochs // 2
            ubx_nav_drive(log, n_epochs, bias=(mid, mid + 59, args.bias_m) if args.bias_m else None)
        else:
            log.write_text("\n".join(straight_drive(n_epochs)) + "\n")
        road_file = Path(tmp) / "roads.geojson"
        road_file.write_text(json.dumps(roads(args.objects, n_epochs * speed)))
        start = time.perf_counter()
        from tollcli.geoobjects.declared_environment import DeclaredEnvironments

        geo = build_geoobjects(str(road_file), environments=DeclaredEnvironments(by_class={"motorway": args.declare}) if args.declare else None)
        t_build = time.perf_counter() - start
        geo_file = Path(tmp) / "geo.geojson"
        geo_file.write_text(json.dumps(geo))
        print(f"drive: {n_epochs} epochs ({log.stat().st_size / 1e6:.0f} MB {'UBX' if args.mix == 'ubx' else 'NMEA'}); network: {len(geo['features'])} geo-objects "
              f"(built in {t_build:.1f} s)")  # fmt: skip
        # as an installed package runs: with its modules' bytecode cached (pip compiles it at install; an
        # editable checkout under PYTHONDONTWRITEBYTECODE=1 would compile every module on every start, ~0.1 s)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["TOLLCLI_CACHE_DIR"] = str(Path(tmp) / "cache")
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(tollcli_package.__file__).parent)],
                       check=False, env=env, stdout=subprocess.DEVNULL)  # fmt: skip
        t_read, m_read = min(timed([*tollcli, "epochs", str(log), "-o", str(Path(tmp) / "e.parquet"), "-q"], env) for _ in range(3))
        with open(log, "rb") as fh:
            n_lines = sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 20), b""))
        process = [*tollcli, "process", str(log), "--geo", str(geo_file), "--tariff", str(tariff), "-q",
                   "--environment", args.environment]  # fmt: skip
        t_cold, m_cold = timed([*process, "-o", str(Path(tmp) / "invoice-cold.json")], env)
        t_proc, m_proc = min(timed([*process, "-o", str(Path(tmp) / "invoice.json")], env) for _ in range(3))
        # the same on one thread (the log's next chunk not read ahead while this one is checked)
        t_one, m_one = min(timed([*process, "-o", str(Path(tmp) / "invoice-one.json")], {**env, "TOLLCLI_READ_AHEAD": "0"}) for _ in range(2))
        one_same = (Path(tmp) / "invoice.json").read_bytes() == (Path(tmp) / "invoice-one.json").read_bytes()
        invoice = json.loads((Path(tmp) / "invoice.json").read_text())
        same = (Path(tmp) / "invoice.json").read_bytes() == (Path(tmp) / "invoice-cold.json").read_bytes()
        print(f"tollcli epochs  (reader, baseline):           {t_read:6.2f} s  {n_epochs / t_read:9,.0f} epochs/s  peak RSS {m_read:6.0f} MB")
        print(f"tollcli process, first run (compiles geo):    {t_cold:6.2f} s  {n_epochs / t_cold:9,.0f} epochs/s  peak RSS {m_cold:6.0f} MB")
        print(f"tollcli process, geo-objects compiled:        {t_proc:6.2f} s  {n_epochs / t_proc:9,.0f} epochs/s  peak RSS {m_proc:6.0f} MB")
        print(f"tollcli process, one thread (READ_AHEAD=0):   {t_one:6.2f} s  {n_epochs / t_one:9,.0f} epochs/s  peak RSS {m_one:6.0f} MB"
              f"  (invoice {'byte-identical' if one_same else 'DIFFERS'})")  # fmt: skip
        print(f"ratio process / reader time: {t_proc / t_read:.2f}; invoice: {len(invoice['lines'])} lines, total {invoice['total']}; "
              f"cold and warm invoices {'byte-identical' if same else 'DIFFER'}")  # fmt: skip
        under = {f["properties"]["id"] for f in geo["features"] if f["properties"]["id"].startswith("R0-")}
        driven = {i for i in under if int(i.split("-")[1]) * 250.0 + 250.0 <= (n_epochs - 1) * speed}  # wholly under the track
        charged = {line["geoobject"] for line in invoice["lines"]}
        declared = f", declared {args.declare}" if args.declare else ""
        whys = sorted({p.get("why", "").split(" (")[0] for p in invoice["not_charged"]})
        print(f"mix {args.mix}{declared}: {len(charged & driven)} of {len(driven)} segments under the track charged "
              f"({len(charged & driven) / max(len(driven), 1):.1%}), {len(charged - under)} on parallel roads; "
              f"findings: {sorted({f['kind'] for f in invoice['findings']['items']}) or 'none'}; "
              f"level {invoice['parameters']['integrity_sources_used']}, vouched by "
              f"{sorted({s for line in invoice['lines'] for s in line['vouched_by']})}; passages not charged: {len(invoice['not_charged'])}"
              f"{', every one saying why' if all(p.get('why') for p in invoice['not_charged']) else ', SOME WITHOUT WHY'}"
              f"{' (' + whys[0][:80] + '…)' if whys else ''}")  # fmt: skip
        if args.mix == "ubx" and args.bias_m:
            import pandas as pd

            table_path = Path(tmp) / "epochs.csv"
            subprocess.run([*tollcli, "integrity", str(log), "-q", "-o", str(table_path)], check=True, env=env)
            table = pd.read_csv(table_path, usecols=["raim_status", "integrity_source"])
            mid = n_epochs // 2
            window, rest = table.iloc[mid : mid + 60], pd.concat([table.iloc[:mid], table.iloc[mid + 60 :]])
            print(f"+{args.bias_m:g} m on one used satellite's prRes for 60 epochs: "
                  f"{dict(window.groupby(['raim_status', 'integrity_source']).size())} in those epochs; "
                  f"elsewhere {dict(rest['raim_status'].value_counts())}")  # fmt: skip
        if args.mix != "ubx":
            t_py = plain_pynmea2(log)
            print(f"pynmea2.parse alone on the same file: {t_py:6.2f} s; ratio process / pynmea2: {t_proc / t_py:.2f} "
                  f"(on one thread {t_one / t_py:.2f}); tollcli epochs {n_lines / t_read:,.0f} lines/s "
                  f"({t_read / t_py:.2f}× pynmea2.parse)")  # fmt: skip
            if args.pairs:
                ratios = paired_ratios([*process, "-o", str(Path(tmp) / "invoice-pair.json")], env, log, args.pairs)
                print(f"paired, each warm process then pynmea2.parse right after it ({args.pairs} pairs): ratios "
                      f"{', '.join(f'{r:.2f}' for r in ratios)}; median {statistics.median(ratios):.2f}")  # fmt: skip
                ratios = paired_ratios([*tollcli, "epochs", str(log), "-o", str(Path(tmp) / "e-pair.parquet"), "-q"], env,
                                       log, args.pairs)  # fmt: skip
                print(f"paired, each tollcli epochs then pynmea2.parse right after it ({args.pairs} pairs): ratios "
                      f"{', '.join(f'{r:.3f}' for r in ratios)}; median {statistics.median(ratios):.3f} "
                      f"(1 M lines/s is {n_lines / 1e6:.2f} s)")  # fmt: skip
        memory = []
        for hours in sorted(args.memory_hours):
            n = int(hours * 3600)
            path = Path(tmp) / f"drive-{hours:g}h.nmea"
            with open(path, "w") as fh:
                for line in straight_drive(n):
                    fh.write(line + "\n")
            t, m = timed([*tollcli, "process", str(path), "--geo", str(geo_file), "--tariff", str(tariff), "-q",
                          "-o", str(Path(tmp) / f"invoice-{hours:g}h.json")], env)  # fmt: skip
            memory.append((hours, m))
            print(f"process, {hours:6g} h drive ({n:,} epochs): {t:7.1f} s, peak RSS {m:7.0f} MB")
            path.unlink()
        if len(memory) > 1:
            print(f"peak RSS ratio {memory[-1][0]:g} h / {memory[0][0]:g} h: {memory[-1][1] / memory[0][1]:.2f}")


if __name__ == "__main__":
    main()
