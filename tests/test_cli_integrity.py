"""``tollcli integrity`` and ``tollcli design`` as a user runs them."""

from __future__ import annotations

import io
import json

import pandas as pd
import pytest

from conftest import SAMPLES, run_cli, shared

SAMPLE = str(SAMPLES / "straight-drive.nmea")


def test_design_classic_known_answer_json():
    proc = run_cli("design", "--dof", "1", "--p-fa", "1e-5", "--p-md", "1e-3", "--json")
    out = json.loads(proc.stdout)
    assert proc.returncode == 0 and out["lambda_det"] ** 0.5 == pytest.approx(7.507, abs=1e-3)


def test_design_etc_and_invoice_chain():
    out = json.loads(run_cli("design", "--dof", "1", "--p-md", "1e-3", "--hal-over-slope", "7", "--json").stdout)
    assert out["p_fa"] == pytest.approx(9.24e-5, rel=1e-2)
    out = json.loads(run_cli("design", "--invoice-share", "99", "--invoice-error", "1", "--n-potential", "10050", "--json").stdout)
    assert out["p_mgor"] == pytest.approx(1e-4, rel=0.02) and out["p_fgor"] == pytest.approx(1e-6, rel=1e-3)
    table = run_cli("design", "--dof", "4", "--p-fa", "5e-3", "--p-md", "5e-5")
    assert table.returncode == 0 and "14.86" in table.stdout.decode()


@pytest.mark.parametrize("args", [["design"], ["design", "--dof", "2"], ["design", "--dof", "1", "--p-md", "2", "--p-fa", "0.1"]])
def test_design_usage_errors(args):
    proc = run_cli(*args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr.decode()


def test_integrity_on_the_sample_nmea(tmp_path):
    out = tmp_path / "raim.parquet"
    proc = run_cli("integrity", SAMPLE, "-o", str(out), "--raim", "classic", "--fde", "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert summary["epochs"] == 180 and summary["raim"] == "classic"
    table = pd.read_parquet(out)
    for column in ("raim_mode", "n_used", "dof", "slope_max_m", "test_stat", "threshold", "hpl_m", "hal_m",
                   "p_fa", "p_md", "raim_status", "excluded_sv", "raim_lat_deg", "n_used_receiver"):  # fmt: skip
        assert column in table.columns
    assert (table["dof"] == 6).all()  # 11 satellites − (3 + 2 clocks: GPS, Galileo)


def test_integrity_gsdc_auto_detected():
    proc = run_cli("integrity", str(shared("gsdc2021", "Pixel4_derived.csv")), "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    table = pd.read_csv(io.BytesIO(proc.stdout))
    assert len(table) == 7 and set(table["raim_status"]) <= {"valid", "fault_detected"}
    assert (table["raim_status"] == "valid").sum() >= 5 and (table["raim_mode"] == "ss").all()
    assert (table["environment"] == "open").all() and (table["variance_factor"] < 1.5).all()
    # the phone's own σ (rawPrUncM) are smaller than its residuals show: its epochs read urban, nothing is valid
    proc = run_cli("integrity", str(shared("gsdc2021", "Pixel4_derived.csv")), "--sigma-model", "input", "-q")
    table = pd.read_csv(io.BytesIO(proc.stdout))
    assert (table["environment"] == "urban").all() and not (table["raim_status"] == "valid").any()
    etc = pd.read_csv(io.BytesIO(run_cli("integrity", str(shared("gsdc2021", "Pixel4_derived.csv")), "--sigma-model", "input",
                                         "--raim", "etc", "--environment", "open", "-q").stdout))  # fmt: skip
    assert set(etc["raim_status"]) == {"valid"}  # the papers' ETC under the phone's σ, as before


@pytest.mark.parametrize(
    "args, code",
    [
        (["integrity", SAMPLE, "--raim", "fancy"], 2),
        (["integrity", SAMPLE, "--p-md", "0"], 2),
        (["integrity", SAMPLE, "--sigma-model", "input"], 2),
        (["integrity", "no-such.nmea"], 2),
        (["integrity", "pyproject.toml"], 1),
    ],
)
def test_integrity_errors(args, code):
    proc = run_cli(*args)
    err = proc.stderr.decode()
    assert proc.returncode == code and "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_the_summary_counts_are_those_of_counting_row_by_row():
    """The statuses, sources, notes and environments `integrity` sums up, counted a column at a time: the same counts in
    the same order as counting each row, on the real chunks of every gpsd NMEA log with a verdict (missing values and
    all) and the simulated urban drive with its fault."""
    from collections import Counter

    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import TALLIED_COLUMNS, iter_integrity, tally_verdicts

    logs = [SAMPLES / "sim" / "urban-fault" / "drive.nmea"] + sorted(p for p in shared("gpsd").iterdir() if p.suffix == ".log")
    tallied = Counter()
    by_row = Counter()
    for log in logs:
        try:
            tables = [c.table for c in iter_integrity(str(log), "nmea", RaimParams())]
        except Exception:  # noqa: BLE001 - not an NMEA log
            continue
        for table in tables:
            tally_verdicts(table, tallied)
            for kind, column in TALLIED_COLUMNS:
                by_row.update((kind, v) for v in table[column].astype(str))
    assert list(tallied.items()) == list(by_row.items())
    assert tallied[("status", "fault_detected")] > 0 and sum(v for (k, _), v in tallied.items() if k == "status") > 2_000
