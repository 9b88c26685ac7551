"""The trajectory's bound on parts of the real Berlin drive: each part a log of its own, as a user could give it.

    python benchmarks/berlin_cuts.py [--lengths 130 160 200 240] [--step 15] [--positioning auto] [--hal 50]
                                     [--without-odometry] [--log DRIVE --truth TRUTH --label NAME]

The Potsdamer Platz drive (``../shared/data/smartloc/Berlin_Potsdamer_Platz_Input.txt``, 283 s at ~5 Hz) cut into
every window of each length, its starts ``--step`` s apart (whole lines: a window is the lines whose time stamp is in
it). Each part is run through the tool's own commands, as a user's log would be: ``tollcli integrity PART -o e.csv``
(defaults; ``--hal``, ``--positioning`` as given; ``--without-odometry``: the parts without their ``odom3`` lines),
then ``tollcli audit --epochs e.csv --truth Berlin_Potsdamer_Platz_GT.txt`` (the truth read by the audit
only). Printed per part: valid epochs, misleading (HPE > HPL among valid), hazardous (HPE > HAL), alarms and the
largest error; then the totals, and where (the drive's own seconds) the misleading epochs were. Writes the table to
``benchmarks/integrity_truth/berlin_cuts.md`` (with the defaults; other settings to ``berlin_cuts-<settings>.md``).

Every bound must hold against every truth: a part of a real drive is a real log. The whole drive is 0 misleading; its
parts are the test the whole is not. ``--log``/``--truth`` cut another libRSF drive the same way (a simulated one:
``benchmarks/integrity_truth/sim/<name>/drive-librsf.txt`` and ``truth-librsf.txt``, written by
``integrity_truth.py``); the table goes to ``cuts-<label>[-<settings>].md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "smartloc"
LOG, TRUTH = DATA / "Berlin_Potsdamer_Platz_Input.txt", DATA / "Berlin_Potsdamer_Platz_GT.txt"
OUT = ROOT / "benchmarks" / "integrity_truth" / "berlin_cuts.md"


def tollcli(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "tollcli", *args], check=True, cwd=ROOT, capture_output=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lengths", type=float, nargs="+", default=[130.0, 160.0, 200.0, 240.0], help="the parts' lengths (s)")
    parser.add_argument("--step", type=float, default=15.0, help="between the parts' starts (s)")
    parser.add_argument("--positioning", default="auto", help="tollcli integrity's --positioning")
    parser.add_argument("--hal", type=float, default=50.0, help="tollcli integrity's --hal (m)")
    parser.add_argument("--without-odometry", action="store_true", help="the parts without their odom3 lines")
    parser.add_argument("--log", type=Path, default=LOG, help="the libRSF drive to cut (default: Berlin Potsdamer Platz)")
    parser.add_argument("--truth", type=Path, default=TRUTH, help="its libRSF truth")
    parser.add_argument("--label", help="the drive's name in the table's file name (default: the log's folder)")
    args = parser.parse_args()
    lines = args.log.read_text().splitlines(keepends=True)
    t_s = np.array([float(line.split()[1]) for line in lines])
    end = float(t_s.max())
    rows, where = [], np.zeros(int(end // 10) + 1, int)
    totals = dict.fromkeys(("epochs", "valid", "misleading", "hazardous", "alarm"), 0)
    with tempfile.TemporaryDirectory() as tmp:
        for length in args.lengths:
            for start in np.arange(0.0, end - length + 1e-9, args.step):
                part, table, audit = Path(tmp, "part.txt"), Path(tmp, "e.csv"), Path(tmp, "a.json")
                keep = (t_s >= start) & (t_s <= start + length)
                part.write_text("".join(line for line, k in zip(lines, keep) if k and not (args.without_odometry and line.startswith("odom3"))))
                tollcli("integrity", str(part), "-o", str(table), "-q", "--positioning", args.positioning, "--hal", f"{args.hal:g}")
                tollcli("audit", "--epochs", str(table), "--truth", str(args.truth), "-q", "-o", str(audit))
                got = json.loads(audit.read_text())["integrity"]
                regions = got["regions"]
                row = {"part": f"{start:.0f}–{start + length:.0f} s", "epochs": got["epochs"], "valid": got["valid"],
                       "misleading": regions["misleading"], "hazardous": regions["hazardous"], "alarm": regions["alarm"],
                       "max_error_m": got["horizontal_error_m"]["max"]}  # fmt: skip
                rows.append(row)
                for key in totals:
                    totals[key] += row[key]
                if row["misleading"]:
                    where += _misleading_by_10_s(table, len(where), args.truth)
                print(f"{row['part']:>12s}: {row['valid']:5d} of {row['epochs']:5d} valid, misleading {row['misleading']:4d}, "
                      f"hazardous {row['hazardous']}, alarms {row['alarm']:3d}, largest error {row['max_error_m']:5.1f} m", flush=True)  # fmt: skip
    share = totals["misleading"] / max(totals["valid"], 1)
    print(f"{len(rows)} parts: {totals['valid']} of {totals['epochs']} epochs valid, {totals['misleading']} misleading "
          f"({100 * share:.1f} % of the valid), {totals['hazardous']} hazardous")  # fmt: skip
    busy = [f"{10 * k}–{10 * k + 10} s: {n}" for k, n in enumerate(where) if n]
    print("misleading epochs by the drive's own time:", "; ".join(busy) or "none")
    _write(rows, totals, busy, args)
    return 0


def _misleading_by_10_s(table: Path, n_bins: int, truth_path: Path) -> np.ndarray:
    """How many of a part's valid epochs are beyond their bound, by 10 s of the drive's own clock."""
    import pandas as pd

    from tollcli.geodesy import geodetic2enu
    from tollcli.readers.librsf import LIBRSF_T0, librsf_truth

    epochs = pd.read_csv(table, parse_dates=["time_utc"])
    truth = librsf_truth(str(truth_path)).set_index("time_utc").reindex(epochs["time_utc"])
    zero = np.zeros(len(epochs))
    e, n, _ = geodetic2enu(epochs["lat_deg"].to_numpy(), epochs["lon_deg"].to_numpy(), zero, truth["lat_deg"].to_numpy(),
                           truth["lon_deg"].to_numpy(), zero)  # fmt: skip
    valid = epochs["raim_status"].isin(["valid", "excluded_valid"]).to_numpy()
    beyond = valid & (np.hypot(e, n) > epochs["hpl_m"].to_numpy())
    seconds = (epochs["time_utc"] - LIBRSF_T0).dt.total_seconds().to_numpy()
    return np.bincount((seconds[beyond] // 10).astype(int), minlength=n_bins)[:n_bins]


def _write(rows, totals, busy, args) -> None:
    settings = [f"--positioning {args.positioning}"] if args.positioning != "auto" else []
    settings += [f"--hal {args.hal:g}"] if args.hal != 50.0 else []
    settings += ["--without-odometry"] if args.without_odometry else []
    tail = "".join(f"-{s.lstrip('-').replace(' ', '-')}" for s in settings)
    if args.log == LOG:
        out = OUT.with_name(f"berlin_cuts{tail}.md")
    else:
        out = OUT.with_name(f"cuts-{args.label or args.log.resolve().parent.name}{tail}.md")
    drive = "the Berlin drive" if args.log == LOG else f"the drive {args.label or args.log.resolve().parent.name}"
    given = [] if args.log == LOG else [f"--log {os.path.relpath(args.log, ROOT)} --truth {os.path.relpath(args.truth, ROOT)}"]
    given += [f"--lengths {' '.join(f'{x:g}' for x in args.lengths)}"] if args.lengths != [130.0, 160.0, 200.0, 240.0] else []
    given += [f"--step {args.step:g}"] if args.step != 15.0 else []
    lines = [f"# The trajectory's bound on parts of {drive}", "",
             f"`python benchmarks/berlin_cuts.py {' '.join(given + settings)}` (lengths {', '.join(f'{x:g}' for x in args.lengths)} s, starts "
             f"{args.step:g} s apart): each part of `{args.log.name}`"
             f"{' without its odom3 lines' if args.without_odometry else ''} a log of its own, through `tollcli integrity` "
             f"(HAL {args.hal:g} m) and `tollcli audit --epochs … --truth {args.truth.name}`.", "",
             "| part | epochs | valid | misleading | hazardous | alarms | largest error (m) |", "|---|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    lines += [f"| {r['part']} | {r['epochs']} | {r['valid']} | {r['misleading']} | {r['hazardous']} | {r['alarm']} | {r['max_error_m']:.1f} |"
              for r in rows]  # fmt: skip
    lines += [f"| **all {len(rows)}** | {totals['epochs']} | {totals['valid']} | **{totals['misleading']}** | {totals['hazardous']} | "
              f"{totals['alarm']} | |", "", "Misleading epochs by the drive's own time: " + ("; ".join(busy) or "none") + "."]  # fmt: skip
    out.write_text("\n".join(lines) + "\n")
    print(f"written {os.path.relpath(out, ROOT)}")


if __name__ == "__main__":
    raise SystemExit(main())
