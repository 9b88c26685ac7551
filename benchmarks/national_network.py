"""A national network on one machine: build, compile, process and batch over 10 000, 50 000 and 150 000 sections.

    python benchmarks/national_network.py                          # 10k, 50k, 150k (≈ 10 min on 2 cores)
    python benchmarks/national_network.py --sections 10000 --hours 1
    python benchmarks/national_network.py --sections 10000 150000 --mix neo-m9n   # the drive issue 49 was measured on

The network is ``process_throughput.roads``: the motorway under the drive and parallel tolled roads 300 m apart, cut
into 250 m sections, scaled to the section count (150 000 sections: 42 roads of 900 km). The drive is the 10 h
25 m/s drive written with a real u-blox ZED-F9P's sentences (``process_throughput.ublox_drive``). For each size,
every command in a fresh process (wall time, peak RSS):

* ``build`` — ``tollcli geoobjects build`` from the road file (it writes the GeoJSON and compiles its store);
* ``compile`` — ``tollcli geoobjects compile`` of that GeoJSON into an empty cache (a file made elsewhere);
* ``first process`` — ``tollcli process`` of the 10 h drive right after the build, then ``warm process`` (best of 2);
* ``batch`` — ``tollcli batch`` of ``--batch-logs`` logs (``--batch-hours`` each) with 2 workers, the workers'
  memory sampled from ``/proc/PID/smaps`` while it runs: per worker its peak RSS, and the part of it that is the
  store's pages (shared by the workers: the proportional share, PSS, is what each costs the machine).

Ratios are printed against the first size (10 000 sections): the warm ``process`` must stay within 1.3× of it, the
first within 2× of the warm one at the same size; and against ``pynmea2.parse`` alone on the same drive (the
reader benchmark's baseline, timed right after each size's warm ``process``, and again in two pairs, each warm
``process`` then ``pynmea2.parse`` right after it): at most 0.5×. The invoices of every size are compared with the first one for
the segments both networks share (the 10 000-section network is a part of every larger one).
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
import threading
import time
from pathlib import Path

from process_throughput import UBLOX_SPEED, roads, timed, ublox_drive  # noqa: E402  (benchmarks/ is on sys.path)
from reader_throughput import plain_pynmea2  # noqa: E402

#: warm process / pynmea2.parse ratios timed back to back per size
PAIRS = 2

TARIFF = Path(__file__).resolve().parents[1] / "geoobjects" / "example-tariff.toml"
TOLLCLI = [sys.executable, "-m", "tollcli"]


def _children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (from /proc)."""
    parent: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            parent.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        kids = parent.get(todo.pop(), [])
        out += kids
        todo += kids
    return out


def _smaps(pid: int, store_marker: str) -> tuple[float, float, float, float]:
    """(RSS, PSS, store RSS, store PSS) of a process, MB."""
    rss = pss = store_rss = store_pss = 0
    mine = False
    try:
        with open(f"/proc/{pid}/smaps") as fh:
            for line in fh:
                if not line[0].isupper():  # a mapping's header line (an address), not a field
                    mine = store_marker in line
                    continue
                key, value = line.split()[:2]
                if key == "Rss:":
                    rss += int(value)
                    store_rss += int(value) if mine else 0
                elif key == "Pss:":
                    pss += int(value)
                    store_pss += int(value) if mine else 0
    except OSError:
        pass
    return rss / 1024, pss / 1024, store_rss / 1024, store_pss / 1024


def batch_memory(cmd: list[str], env: dict, store_marker: str) -> dict:
    """Run a batch, sampling its workers' memory every 0.2 s: wall time and each worker's peaks."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    peaks: dict[int, list[float]] = {}
    together = [0.0, 0.0]  # the largest sum over the workers at one moment of the store's RSS, and of its PSS
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            now = [0.0, 0.0]
            for pid in _children(proc.pid):
                values = _smaps(pid, store_marker)
                old = peaks.setdefault(pid, [0.0] * 4)
                peaks[pid] = [max(a, b) for a, b in zip(old, values)]
                now = [now[0] + values[2], now[1] + values[3]]
            if now[0] > together[0]:
                together[:] = now
            time.sleep(0.2)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    _, err = proc.communicate()
    stop.set()
    thread.join()
    if proc.returncode != 0:
        raise SystemExit(f"batch failed: {err.decode()[-500:]}")
    workers = sorted(peaks.values(), key=lambda v: -v[0])[:2]
    return {"seconds": time.perf_counter() - start, "workers": workers, "store_together": together}


def run_size(n: int, work: Path, drive: Path, batch_logs: list[Path], env0: dict) -> dict:
    folder = work / f"n{n}"
    folder.mkdir()
    road_file, geo_file = folder / "roads.geojson", folder / "geo.geojson"
    length_m = 36000 * UBLOX_SPEED
    road_file.write_text(json.dumps(roads(n, length_m)))
    env = {**env0, "TOLLCLI_CACHE_DIR": str(folder / "cache")}
    out: dict = {"sections": n}
    out["build"] = timed([*TOLLCLI, "geoobjects", "build", str(road_file), "-o", str(geo_file), "-q"], env)
    out["geojson_mb"] = geo_file.stat().st_size / 1e6
    out["compile"] = timed([*TOLLCLI, "geoobjects", "compile", str(geo_file), "-q"], {**env0, "TOLLCLI_CACHE_DIR": str(folder / "cache2")})
    process = [*TOLLCLI, "process", str(drive), "--geo", str(geo_file), "--tariff", str(TARIFF), "-q"]
    out["first"] = timed([*process, "-o", str(folder / "invoice-first.json")], env)
    out["warm"] = min(timed([*process, "-o", str(folder / "invoice.json")], env) for _ in range(2))
    out["pynmea2"] = plain_pynmea2(drive)
    # the same ratio timed in pairs, each warm process then pynmea2 right after it (a shared machine's speed drifts)
    out["pairs"] = [timed([*process, "-o", str(folder / "invoice-pair.json")], env)[0] / plain_pynmea2(drive) for _ in range(PAIRS)]
    out["invoice"] = json.loads((folder / "invoice.json").read_text())
    out["first_same"] = (folder / "invoice.json").read_bytes() == (folder / "invoice-first.json").read_bytes()
    batch = [*TOLLCLI, "batch", *map(str, batch_logs), "--geo", str(geo_file), "--tariff", str(TARIFF), "-o", str(folder / "batch"),
             "--workers", "2", "-q"]  # fmt: skip
    out["batch"] = batch_memory(batch, env, "/geoobjects/")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sections", type=int, nargs="+", default=[10_000, 50_000, 150_000])
    parser.add_argument("--hours", type=float, default=10.0, help="the drive processed, h")
    parser.add_argument("--batch-logs", type=int, default=20)
    parser.add_argument("--batch-hours", type=float, default=0.5, help="each batch log's length, h")
    parser.add_argument("--workdir", default=tempfile.gettempdir())
    parser.add_argument("--mix", choices=("ublox", "neo-m9n"), default="ublox",
                        help="the drive's sentences: the ZED-F9P's, or the same without its second band's GSV lines (as "
                             "process_throughput.py --mix neo-m9n: 828 000 lines in 10 h)")  # fmt: skip
    args = parser.parse_args()
    env0 = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    import tollcli as tollcli_package

    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(tollcli_package.__file__).parent)], check=False,
                   env=env0, stdout=subprocess.DEVNULL)  # fmt: skip
    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        work = Path(tmp)
        drive = work / "drive.nmea"
        single_band = args.mix == "neo-m9n"
        ublox_drive(drive, int(args.hours * 3600), single_band=single_band)
        short = work / "short.nmea"
        ublox_drive(short, int(args.batch_hours * 3600), single_band=single_band)
        (work / "logs").mkdir()
        batch_logs = []
        for i in range(args.batch_logs):
            log = work / "logs" / f"VEH-{i:03d}.nmea"
            os.link(short, log)
            batch_logs.append(log)
        print(f"drive: {int(args.hours * 3600)} epochs, {drive.stat().st_size / 1e6:.0f} MB of u-blox ZED-F9P NMEA"
              f"{' without its second band' if single_band else ''}; "
              f"batch: {args.batch_logs} logs of {args.batch_hours:g} h, 2 workers")  # fmt: skip
        results = []
        for n in args.sections:
            r = run_size(n, work, drive, batch_logs, env0)
            results.append(r)
            base = results[0]
            w = r["batch"]["workers"]
            print(f"\n{n:,} sections ({r['geojson_mb']:.0f} MB GeoJSON)")
            for key, label in (("build", "geoobjects build"), ("compile", "geoobjects compile"), ("first", "process, first"),
                               ("warm", "process, warm")):  # fmt: skip
                t, m = r[key]
                print(f"  {label:22s} {t:7.2f} s  peak RSS {m:6.0f} MB   ({t / base[key][0]:.2f}× the {base['sections']:,}-section time)")
            print(f"  first / warm process: {r['first'][0] / r['warm'][0]:.2f} (invoices {'byte-identical' if r['first_same'] else 'DIFFER'})")
            print(f"  pynmea2.parse alone on the drive: {r['pynmea2']:.2f} s; warm process / pynmea2: {r['warm'][0] / r['pynmea2']:.2f}; "
                  f"in {PAIRS} pairs timed back to back: {', '.join(f'{x:.2f}' for x in r['pairs'])}, median {statistics.median(r['pairs']):.2f}")  # fmt: skip
            print(f"  batch, 2 workers:     {r['batch']['seconds']:7.2f} s  ({r['batch']['seconds'] / base['batch']['seconds']:.2f}×); per worker "
                  + "; ".join(f"peak RSS {v[0]:.0f} MB of which the store's pages {v[2]:.0f} MB" for v in w)
                  + f"; the store's pages in both at once: RSS {r['batch']['store_together'][0]:.0f} MB, PSS "
                  f"{r['batch']['store_together'][1]:.0f} MB (shared: each pays half)")  # fmt: skip
            lines = {(x["geoobject"], x["entry_utc"]): x["fee"] for x in r["invoice"]["lines"]}
            base_lines = {(x["geoobject"], x["entry_utc"]): x["fee"] for x in base["invoice"]["lines"]}
            same = all(lines.get(k) == v for k, v in base_lines.items())
            print(f"  invoice: {len(lines)} lines, total {r['invoice']['total']}; the {len(base_lines)} lines of the "
                  f"{base['sections']:,}-section network {'all the same' if same else 'DIFFER'}")  # fmt: skip
        if math.isfinite(results[-1]["warm"][0]):
            print(f"\nwarm process at {results[-1]['sections']:,} / {results[0]['sections']:,} sections: "
                  f"{results[-1]['warm'][0] / results[0]['warm'][0]:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
