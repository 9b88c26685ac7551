"""Writing tables as CSV: the compiled pass (``tollcli/io/csv_rows.py``) against the writers it stands in for, the csv
module (epoch and satellite tables, numpy columns) and pandas' ``to_csv`` (integrity tables, DataFrames), on the same
tables in the same run.

    python benchmarks/csv_writing.py [--hours 10] [--rounds 5]

The tables: those of a ``--hours`` long 1 Hz drive written with a real u-blox NEO-M9N's sentences (the drive of
``process_throughput.py --mix neo-m9n``: 23 lines an epoch), read once; its epoch table (36 columns), its satellite
table and its integrity table (70 columns). Each is written whole through :class:`~tollcli.io.writers.TableWriter` to
a file, with the kernel and without it (``csv_rows.compiled = None``: the reference the kernel replaced), alternating,
``--rounds`` times; prints the medians, their ratio, and whether the files are byte-identical. (The commands as whole
processes against the code before: docs/scaling.md.)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from tollcli.io import csv_rows  # noqa: E402
from tollcli.io.writers import TableWriter  # noqa: E402


def written_s(table, path: Path, compiled) -> float:
    """Seconds to write ``table`` whole to ``path`` as CSV (the kernel: ``compiled``; None: the reference)."""
    saved = csv_rows.compiled
    csv_rows.compiled = compiled
    try:
        start = time.perf_counter()
        with TableWriter(str(path), "csv") as writer:
            writer.write(table)
            writer.commit()
        return time.perf_counter() - start
    finally:
        csv_rows.compiled = saved


def tables(log: Path):
    """The drive's epoch and satellite tables (numpy columns, whole) and its integrity table (a DataFrame)."""
    import numpy as np
    import pandas as pd

    from tollcli.integrity.raim import RaimParams
    from tollcli.io.columns import Columns
    from tollcli.io.log_run import LogRun
    from tollcli.job.log_integrity import iter_integrity
    from tollcli.readers.navigation import iter_epoch_tables

    with LogRun(str(log), "auto", hashed=False) as run:
        chunks = list(iter_epoch_tables(run))

    def joined(name: str) -> Columns:
        parts = [getattr(c, name) for c in chunks]
        return Columns({k: np.concatenate([p[k] for p in parts]) for k in parts[0].columns})

    integrity = pd.concat([c.table for c in iter_integrity(str(log), "nmea", RaimParams())], ignore_index=True)
    return {"epoch table (numpy columns; csv module)": joined("epoch_columns"),
            "satellite table (numpy columns; csv module)": joined("satellite_columns"),
            "integrity table (DataFrame; pandas to_csv)": integrity}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    if csv_rows.compiled is None:
        sys.exit("the compiled CSV kernel is not built here (python setup.py build_ext --inplace)")
    import process_throughput

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "drive.nmea"
        n_epochs = int(args.hours * 3600)
        process_throughput.ublox_drive(log, n_epochs, single_band=True)
        print(f"drive: {n_epochs} epochs, {os.path.getsize(log) / 1e6:.0f} MB NMEA (NEO-M9N sentences)")
        for name, table in tables(log).items():
            fast, ref = [], []
            for _ in range(args.rounds):
                fast.append(written_s(table, Path(tmp) / "fast.csv", csv_rows.compiled))
                ref.append(written_s(table, Path(tmp) / "ref.csv", None))
            same = (Path(tmp) / "fast.csv").read_bytes() == (Path(tmp) / "ref.csv").read_bytes()
            size = os.path.getsize(Path(tmp) / "fast.csv") / 1e6
            f, r = statistics.median(fast), statistics.median(ref)
            print(f"{name}: {len(table)} rows, {size:.0f} MB; compiled {f:.3f} s, reference {r:.3f} s: ratio {f / r:.3f}"
                  f" ({'byte-identical' if same else 'DIFFERENT'})")  # fmt: skip


if __name__ == "__main__":
    main()
