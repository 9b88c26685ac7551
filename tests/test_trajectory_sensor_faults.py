"""The trajectory estimator when the vehicle's own sensors go wrong: simulated city drives (``tollcli simulate --nlos
--odometry``) whose odometer reads 10 % too much, or whose gyro's bias jumps by 0.02 rad/s (1.1 °/s), for a minute,
or both at once. Each fault is detected while it lasts or its error stays within the bound: no misleading or
hazardous epoch, whichever positioning, audited against the drive's truth.

Each case found a failure once:
* both at once: a pass that has drifted off rejects every later measurement with its robust loss and never comes back
  (the whole drive's median error 32 m, against 8 m fault-free): a pass that rejects most of an epoch's measurements
  now widens its prior and lets them take it back;
* the gyro's bias: the two passes' positions agreed while their headings did not (the pass run backward integrates
  the bias the other way): the fault test compares the headings too;
* a stronger gyro fault (0.05 rad/s): 22 misleading epochs where both passes were inside the fault, before either had
  lost the vehicle: the epochs within 30 s of where a pass lost it are a fault;
* ``--positioning filtered``: the forward pass's own bound did not cover a 3 % odometer error (105 misleading): its
  bound now goes through the smoothed one (HPL ≥ distance to the smoothed position + the smoothed HPL).
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pandas as pd
import pytest
from conftest import run_cli

#: the drives: extra ``simulate`` options, and when the sensors were wrong (s from the start)
DRIVES = {
    "odometer": (("--sensor-fault-at", "200", "--odometer-step", "0.1"), [(200.0, 260.0)]),
    "gyro": (("--sensor-fault-at", "400", "--gyro-step", "0.02"), [(400.0, 460.0)]),
    "both": (("--sensor-fault-at", "200,400", "--odometer-step", "0.1", "--gyro-step", "0.02"), [(200.0, 260.0), (400.0, 460.0)]),
}  # fmt: skip


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    root = tmp_path_factory.mktemp("sensor-faults")
    out = {}
    for name, (extra, _) in DRIVES.items():
        folder = root / name
        proc = run_cli("simulate", "--nlos", "--odometry", "--duration", "600", "--rate", "2", "--seed", "21",
                       "--sensor-fault-duration", "60", *extra, "-o", str(folder), "-q")  # fmt: skip
        assert proc.returncode == 0, proc.stderr.decode()
        out[name] = folder
    return out


def _run(folder, positioning: str, log: str = "drive-librsf.txt", *options: str) -> tuple[list[dict], dict]:
    table, report = folder / f"{positioning}.csv", folder / f"{positioning}.json"
    proc = run_cli("integrity", str(folder / log), "--positioning", positioning, "-o", str(table), "-q", *options)
    assert proc.returncode == 0, proc.stderr.decode()
    proc = run_cli("audit", "--epochs", str(table), "--truth", str(folder / "truth-librsf.txt"), "-o", str(report), "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    return rows, json.loads(report.read_text())["integrity"]


@pytest.mark.parametrize("positioning", ["smoothed", "filtered"])
@pytest.mark.parametrize("name", sorted(DRIVES))
def test_a_sensor_fault_is_detected_or_bounded(drives, name, positioning):
    rows, audit = _run(drives[name], positioning)
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0, audit["regions"]
    time = pd.to_datetime([r["time_utc"] for r in rows])
    t = np.asarray((time - time[0]).total_seconds())
    inside = np.zeros(t.size, bool)
    for lo, hi in DRIVES[name][1]:
        inside |= (t >= lo) & (t < hi)
    status = np.array([r["raim_status"] for r in rows])
    assert inside.sum() >= 100
    # the fault is seen: all of the odometer's and the gyro's epochs (240/240 and 120/120 measured), most of both's
    assert (status[inside] == "fault_detected").mean() >= (0.95 if name != "both" else 0.8), name
    assert (status[~inside] == "valid").mean() >= 0.5  # and the drive stays usable around it


def test_a_pass_that_lost_the_vehicle_takes_it_back(drives):
    """Both sensors wrong at once: the smoothed positions of the whole drive stay as good as a fault-free drive's
    (median 8 m; 32 m when a pass that had drifted off kept rejecting the measurements)."""
    _, audit = _run(drives["both"], "smoothed")
    assert audit["horizontal_error_m"]["median"] <= 10.0


#: parts of the drives (s from the start) that end or start near their sensor's fault, and the HAL they were judged at:
#: the older pass, alone near an end, had crossed the fault (before the fault test's verdict from beyond the end's window
#: reached it: 11 hazardous epochs at HAL 50 m; 18 misleading, 14 of them hazardous, at HAL 30 m)
PARTS = {"odometer": (50.0, 250.0, "50"), "gyro": (300.0, 430.0, "30")}


@pytest.mark.parametrize("name", sorted(PARTS))
def test_a_log_that_ends_after_a_sensor_fault_is_bounded(drives, name):
    """A log is a part of a drive: cut near its sensor's fault, no misleading or hazardous epoch."""
    start, end, hal = PARTS[name]
    lines = (drives[name] / "drive-librsf.txt").read_text().splitlines(keepends=True)
    (drives[name] / "part.txt").write_text("".join(line for line in lines if start <= float(line.split()[1]) <= end))
    rows, audit = _run(drives[name], "smoothed", "part.txt", "--hal", hal)
    assert audit["regions"]["misleading"] == 0 and audit["regions"]["hazardous"] == 0, audit["regions"]
    assert audit["valid"] >= 0.3 * len(rows)
