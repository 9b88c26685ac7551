"""``tollcli batch`` throughput with 1 and 2 local workers and on a Dask LocalCluster, on the same logs.

    python benchmarks/batch_throughput.py --logs 1000 --workdir /tmp

The logs are the four bundled simulated drives (samples/sim/, 230 epochs each), copied under
distinct vehicle names. Prints logs/s and epochs/s per configuration, the 2-worker speed-up, and
whether every output file is byte-identical between the local pool and the Dask cluster.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from tollcli.job.batch import expand_inputs, run_batch
from tollcli.job.pipeline import ChargeSettings

REPO = Path(__file__).resolve().parents[1]


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=1000)
    parser.add_argument("--workdir", default=tempfile.gettempdir())
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="tollcli-batch-", dir=args.workdir))
    src = [REPO / "samples" / "sim" / n / "drive.nmea" for n in ("rural-clean", "urban-clean", "urban-fault", "rural-fault")]
    logs_dir = work / "logs"
    logs_dir.mkdir()
    for i in range(args.logs):
        shutil.copy(src[i % 4], logs_dir / f"VEH-{i:05d}.nmea")
    logs = expand_inputs([str(logs_dir)])
    geo, tariff = str(REPO / "geoobjects" / "example-geoobjects.geojson"), str(REPO / "geoobjects" / "example-tariff.toml")
    results = {}
    for label, kwargs in (("local, 1 worker", {"workers": 1}), ("local, 2 workers", {"workers": 2})):
        out = work / label.replace(", ", "-").replace(" ", "")
        t0 = time.perf_counter()
        summary = run_batch(logs, geo, tariff, ChargeSettings(), str(out), **kwargs)
        results[label] = (time.perf_counter() - t0, summary, out)
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        out = work / "dask"
        t0 = time.perf_counter()
        summary = run_batch(logs, geo, tariff, ChargeSettings(), str(out), scheduler=cluster.scheduler_address)
        results["Dask LocalCluster, 2 workers"] = (time.perf_counter() - t0, summary, out)
    epochs = sum(o.get("epochs", 0) for o in results["local, 1 worker"][1]["outcomes"])
    print(f"{args.logs} logs, {epochs} epochs ({os.cpu_count()} cores)")
    base = results["local, 1 worker"][0]
    for label, (secs, summary, _) in results.items():
        print(f"{label:32s} {secs:7.1f} s  {args.logs / secs:7.1f} logs/s  {epochs / secs:9.0f} epochs/s  "
              f"speed-up {base / secs:4.2f}  ({summary['done']} done, {summary['failed']} failed, {summary['totals']})")
    ref = _files(results["local, 1 worker"][2])
    for label in list(results)[1:]:
        same = _files(results[label][2]) == ref
        print(f"outputs of '{label}' byte-identical to 'local, 1 worker': {same} ({len(ref)} files)")
    shutil.rmtree(work)


if __name__ == "__main__":
    main()
