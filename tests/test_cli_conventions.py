"""At home among gpsd, RTKLIB and GDAL tools: -f/--format, streams, settings files, info, --json, exit codes."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from conftest import run_cli

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared" / "data"
SAMPLE = str(REPO / "samples" / "straight-drive.nmea")
URBAN = str(REPO / "samples" / "sim" / "urban-fault" / "drive.nmea")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
CHARGE = ["--geo", GEO, "--tariff", TARIFF]


def shared(*parts: str) -> Path:
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} not present (shared data)")
    return path


# ---------------------------------------------------------------- formats and streams
def test_parquet_and_geojson_sequence_stream_to_a_pipe():
    """`-f parquet -o -` writes a Parquet file to a pipe that pyarrow reads; GeoJSONSeq is one Feature per line."""
    cmd = (f"{sys.executable} -m tollcli epochs {SAMPLE} -f parquet -o - -q | {sys.executable} -c "
           "'import io, sys, pyarrow.parquet as pq; t = pq.read_table(io.BytesIO(sys.stdin.buffer.read()), use_threads=False); "
           "print(t.num_rows, t.column(\"lat_deg\")[0])'")
    proc = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split()[0] == b"180"
    seq = run_cli("epochs", SAMPLE, "-f", "GeoJSONSeq", "-q")  # GDAL's driver name
    lines = seq.stdout.decode().splitlines()
    assert seq.returncode == 0 and len(lines) == 180
    first = json.loads(lines[0])
    assert first["type"] == "Feature" and first["geometry"]["coordinates"] == [2.8956, pytest.approx(42.6987, abs=1e-12)]


def test_format_flag_wins_over_the_extension_and_devices_are_written_to(tmp_path):
    out = tmp_path / "epochs.txt"  # no table extension: -f names it
    assert run_cli("epochs", SAMPLE, "-f", "csv", "-o", str(out), "-q").returncode == 0
    assert out.read_text().startswith("epoch,time_utc,")
    bad = run_cli("epochs", SAMPLE, "-o", str(tmp_path / "e.txt"), "-q")
    assert bad.returncode == 2 and b"name it with -f" in bad.stderr
    wrong = run_cli("process", SAMPLE, *CHARGE, "-f", "parquet", "-o", "-", "-q")
    assert wrong.returncode == 2 and b"json, csv" in wrong.stderr
    for args in (["epochs", SAMPLE], ["integrity", SAMPLE], ["process", SAMPLE, *CHARGE], ["findings", SAMPLE],
                 ["locate", SAMPLE], ["geoobjects", "build", str(REPO / "geoobjects" / "example-roads.geojson")]):
        proc = run_cli(*args, "-o", "/dev/null", "-q")
        assert proc.returncode == 0, (args, proc.stderr)
    assert Path("/dev/null").exists() and not Path("/dev/null").is_file()  # still the device, never renamed over


def test_the_input_format_keeps_its_old_spelling():
    """--input-format names the log's kind; --format with an input kind still does (old scripts), not both at odds."""
    a = run_cli("integrity", SAMPLE, "--input-format", "nmea", "-q")
    b = run_cli("integrity", SAMPLE, "--format", "nmea", "-q")
    assert a.returncode == b.returncode == 0 and a.stdout == b.stdout
    clash = run_cli("integrity", SAMPLE, "--format", "nmea", "--input-format", "ubx-nav", "-q")
    assert clash.returncode == 2 and b"--input-format" in clash.stderr


def test_csv_numbers_are_as_the_log_wrote_them():
    """No float noise: the NMEA 4241.9220000 is 42.6987 in CSV (Parquet keeps the double)."""
    text = run_cli("epochs", SAMPLE, "-q").stdout.decode()
    first = next(csv.DictReader(io.StringIO(text)))
    assert first["lat_deg"] == "42.6987" and first["lon_deg"] == "2.8956"
    assert not re.search(r"\d\.\d*(9{6,}|0{6,})\d", text), "float noise in the CSV"


def test_findings_as_points_for_a_gis(tmp_path):
    out = tmp_path / "findings.geojson"
    proc = run_cli("findings", URBAN, "--geo", GEO, "-o", str(out), "--json")
    summary = json.loads(proc.stdout)
    doc = json.loads(out.read_text())
    assert proc.returncode == 0 and summary["findings"] == len(doc["features"]) > 0
    assert all(f["properties"]["kind"] for f in doc["features"]) and doc["features"][0]["geometry"]["type"] == "Point"
    table = run_cli("findings", URBAN, "--geo", GEO, "-f", "csv", "-q").stdout.decode()
    assert len(list(csv.DictReader(io.StringIO(table)))) == summary["findings"]


# ---------------------------------------------------------------- settings files
def _process(tmp_path, name, *args):
    out = tmp_path / name
    proc = run_cli("process", URBAN, *CHARGE, "-o", str(out), "-q", *args)
    assert proc.returncode == 0, proc.stderr
    return out.read_bytes()


def test_a_settings_file_gives_the_run_of_the_same_flags(tmp_path):
    flags = ["--raim", "classic", "--tc", "3", "--p-md", "1e-4", "--vehicle-class", "van", "--environment", "open"]
    settings = tmp_path / "settings.toml"
    settings.write_text('raim = "classic"\ntc = 3.0\np_md = 1e-4\nvehicle-class = "van"\n[process]\nenvironment = "open"\n'
                        "[integrity]\nhal = 30\n")
    by_flags = _process(tmp_path, "flags.json", *flags)
    assert _process(tmp_path, "file.json", "--config", str(settings)) == by_flags
    assert _process(tmp_path, "default.json") != by_flags  # the settings matter
    # the command line wins over the file
    assert _process(tmp_path, "mixed.json", "--config", str(settings), "--raim", "ss") == _process(tmp_path, "ss.json", *flags[2:])
    # integrity reads its own table and the shared keys
    a = run_cli("integrity", URBAN, "--config", str(settings), "-q").stdout
    b = run_cli("integrity", URBAN, "--raim", "classic", "--p-md", "1e-4", "--hal", "30", "-q").stdout
    assert a == b and b"30" in a


def test_an_invoice_fed_back_gives_the_same_invoice(tmp_path):
    first = _process(tmp_path, "first.json", "--raim", "etc", "--n-th", "2", "--vehicle", "TRK-9", "--fde")
    params = json.loads(first)["parameters"]
    assert params["raim"] == "etc" and params["vehicle"] == "TRK-9" and "policy_used" in params
    assert _process(tmp_path, "again.json", "--config", str(tmp_path / "first.json")) == first


def test_settings_files_say_what_is_wrong(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("p_mdd = 1e-4\n")
    proc = run_cli("process", SAMPLE, *CHARGE, "--config", str(bad))
    assert proc.returncode == 2 and b"'p_mdd' is no option" in proc.stderr and b"Traceback" not in proc.stderr
    bad.write_text("raim = \n")
    assert b"not TOML" in run_cli("integrity", SAMPLE, "--config", str(bad)).stderr
    assert run_cli("integrity", SAMPLE, "--config", str(tmp_path / "missing.toml")).returncode == 2


def test_batch_has_every_charging_option_of_process():
    from tollcli.cli.batch import batch
    from tollcli.cli.process import process

    only_process = {"log", "output", "out_fmt", "as_json"}  # one log, one invoice file and its summary
    missing = set(process.__annotations__) - set(batch.__annotations__) - only_process - {"return"}
    assert not missing, f"batch lacks {sorted(missing)}"


def test_batch_runs_from_an_invoice(tmp_path):
    inv = tmp_path / "inv.json"
    assert run_cli("process", SAMPLE, *CHARGE, "--raim", "etc", "--tc", "4", "-o", str(inv), "-q").returncode == 0
    out = tmp_path / "out"
    proc = run_cli("batch", SAMPLE, *CHARGE, "-o", str(out), "--workers", "1", "--config", str(inv), "-q")
    assert proc.returncode == 0, proc.stderr
    charged = json.loads(next((out / "invoices").rglob("*.json")).read_text())
    assert {k: charged["parameters"][k] for k in ("raim", "tc_s")} == {"raim": "etc", "tc_s": 4.0}
    assert charged["lines"] == json.loads(inv.read_text())["lines"]


# ---------------------------------------------------------------- info
EXPECTED_KINDS = {("android", "pixel6.nmea"): "nmea", ("android", "pixel6.23o"): "rinex",
                  ("android", "pixel6_gnsslogger.txt"): "gnsslogger", ("gsdc2022", "device_gnss.csv"): "device-gnss",
                  ("gsdc2021", "Pixel4_derived.csv"): "gsdc-derived", ("smartloc", "Berlin_Potsdamer_Platz_Input.txt"): "librsf",
                  ("gpsd", "ublox-neo-m8t.log"): "ubx", ("gpsd", "sirf2.log"): "gpsd-binary" if shutil.which("gpsdecode") else "unknown"}  # fmt: skip


def test_info_on_every_shared_file():
    """Every file of the shared data gets an answer (no error), each kind the right one."""
    from tollcli.job.file_info import file_info

    shared("gpsd")
    kinds: dict[str, int] = {}
    for path in sorted(p for p in SHARED.rglob("*") if p.is_file() and "osnma" not in p.parts):
        info = file_info(str(path))
        kinds[info["kind"]] = kinds.get(info["kind"], 0) + 1
        if info["kind"] in ("nmea", "ubx-nav", "gpsd-json"):
            assert info["integrity_level"] in ("residual", "receiver", "covariance", "model", "none")
            if not info.get("problem"):  # every epoch with a GGA quality counted once by it, positions among the epochs
                assert sum(info["fix_quality"].values()) <= info["epochs"] >= info["epochs_with_position"]
                assert all(int(k) >= 0 for k in info["fix_quality"])  # no sentinel for "no GGA"
                assert all(v <= info["epochs"] for v in info["integrity_evidence_epochs"].values())
            if info["epochs_with_position"] > 1 and info["interval_s"]:
                assert 0 < info["interval_s"] <= info["span_s"]
    for parts, kind in EXPECTED_KINDS.items():
        assert file_info(str(shared(*parts)))["kind"] == kind, parts
    assert {"nmea", "gpsd-json", "ubx-nav", "rinex", "gnsslogger", "device-gnss", "ubx", "librsf"} <= set(kinds)


def test_info_of_a_log_a_geo_object_file_and_an_invoice(tmp_path):
    proc = run_cli("info", SAMPLE, "--json")
    info = json.loads(proc.stdout)
    assert proc.returncode == 0 and info["kind"] == "nmea" and info["epochs"] == 180 and info["interval_s"] == 1.0
    assert info["messages"]["GGA"] == 180 and info["integrity_level"] == "covariance" and info["skipped_lines"] == 1
    text = run_cli("info", SAMPLE).stdout.decode()
    assert "messages: " in text and "level under --integrity-sources auto: covariance" in text
    geo = json.loads(run_cli("info", GEO, "--json").stdout)
    assert geo["kind"] == "geoobjects" and geo["geoobjects"] == 2
    inv = tmp_path / "inv.json"
    run_cli("process", SAMPLE, *CHARGE, "-o", str(inv), "-q")
    doc = json.loads(run_cli("info", str(inv), "--json").stdout)
    assert doc["kind"] == "invoice" and doc["total"] == json.loads(inv.read_text())["total"]


# ---------------------------------------------------------------- --json summaries
def test_json_summaries_on_every_command_that_writes(tmp_path):
    inv = tmp_path / "inv.json"
    got = json.loads(run_cli("process", URBAN, *CHARGE, "-o", str(inv), "--json").stdout)
    doc = json.loads(inv.read_text())
    assert got["total"] == doc["total"] and got["content_sha256"] == doc["content_sha256"] and got["output"] == str(inv)
    assert json.loads(run_cli("audit", str(inv), "-o", str(tmp_path / "a.json"), "--json").stdout)["runs"] == 1
    assert json.loads(run_cli("report", str(inv), "-o", str(tmp_path / "r.html"), "--json").stdout)["epochs"] > 0
    figures = json.loads(run_cli("plot", str(inv), "-o", str(tmp_path / "figs"), "-f", "svg", "--json").stdout)["figures"]
    assert figures and all(f.endswith(".svg") and Path(f).read_text().lstrip().startswith("<?xml") for f in figures)
    assert "findings" in json.loads(run_cli("findings", URBAN, "-o", str(tmp_path / "f.json"), "--json").stdout)
    for args in (["process", URBAN, *CHARGE], ["findings", URBAN], ["audit", str(inv)], ["report", str(inv)]):
        proc = run_cli(*args, "-o", "-", "--json")  # both on stdout: refused, saying why
        assert proc.returncode == 2 and b"--json" in proc.stderr, args


# ---------------------------------------------------------------- help, man pages, exit codes
def test_exit_codes_are_the_same_in_help_man_pages_and_readme():
    from tollcli.cli.app import EPILOG
    from tollcli.cli.manpage import EXIT_STATUS

    in_help = re.findall(r"(\d) [a-z]", EPILOG.split(":", 1)[1])
    readme = re.findall(r"^\| (\d) \|", (REPO / "README.md").read_text(), flags=re.M)
    assert in_help == [c for c, _ in EXIT_STATUS] == readme == ["0", "1", "2", "3", "4", "5", "6"]
    for page in (REPO / "man").glob("*.1"):
        assert re.findall(r"^\\fB(\d)\\fR$", page.read_text(), flags=re.M) == in_help, page.name


def test_help_texts_print_as_written():
    for command in ("audit", "process", "integrity", "info", "epochs"):
        proc = run_cli(command, "--help")
        assert proc.returncode == 0 and b"%%" not in proc.stdout, command
    assert b"percentage of the true total" in run_cli("audit", "--help").stdout


# ---------------------------------------------------------------- figures and terminal
def test_plots_label_longitude_plainly_and_draw_etc_against_the_classic_hpl(tmp_path, monkeypatch):
    from tollcli.report import plots
    from tollcli.report.run_data import load_run

    inv = tmp_path / "etc.json"
    assert run_cli("process", URBAN, *CHARGE, "--raim", "etc", "-o", str(inv), "-q").returncode == 0
    kept = []
    monkeypatch.setattr(plots, "_save", lambda fig, outdir, name, fmt="png": kept.append(fig) or name)
    plots.write_plots(load_run(str(inv)), str(tmp_path / "figs"))
    trajectory, protection = kept[0], kept[1]
    assert trajectory.axes[0].xaxis.get_major_formatter().get_useOffset() is False
    ax = protection.axes[0]
    hpl = next(line for line in ax.get_lines() if "classic HPL" in line.get_label()).get_ydata()
    hal = next(line for line in ax.get_lines() if line.get_label() == "HAL (m)").get_ydata()
    finite = pd.Series(hpl).dropna()
    assert finite.nunique() > 1 and not (finite == hal[0]).all()  # not a flat line on the HAL


def test_the_map_legend_names_the_truth(tmp_path):
    inv = tmp_path / "inv.json"
    run_cli("process", URBAN, *CHARGE, "-o", str(inv), "-q")
    page = tmp_path / "r.html"
    assert run_cli("report", str(inv), "--truth", str(REPO / "samples" / "sim" / "urban-fault" / "truth.csv"), "-o", str(page)).returncode == 0
    assert "truth<br>" in page.read_text()


def test_progress_shows_a_percentage_when_the_size_is_known(monkeypatch, tmp_path):
    from rich.console import Console

    from tollcli.cli import console

    log = tmp_path / "log.nmea"
    log.write_text("x\n" * 200)
    screen = io.StringIO()
    monkeypatch.setattr(console, "err", Console(file=screen, force_terminal=True, width=100))
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    with console.progress("reading", False, log=str(log)) as advance:
        advance(10, 100)
        console.err.file.flush()
        assert console._line_count(str(log)) == 200
    assert "%" in screen.getvalue()


def test_terminal_tables_never_cut_the_times():
    from rich.console import Console

    from tollcli.cli.console import invoice_tables

    invoice = {"vehicle": "TRK-042", "vehicle_class": "truck", "currency": "EUR", "total": "2.38", "not_charged": [],
               "lines": [{"geoobject": "A9-NORTH-SECTION-1", "entry_utc": "2024-05-06T08:00:00.000Z", "exit_utc": "2024-05-06T08:01:26.000Z",
                          "n_valid_independent": 16, "band": "peak", "fee": "0.95", "statuses": {"valid": 80}}]}  # fmt: skip
    screen = Console(file=io.StringIO(), width=80, force_terminal=False)
    for table in invoice_tables(invoice):
        screen.print(table)
    text = screen.file.getvalue()
    assert "2024-05-06T08:00:00.000Z" in text and "2024-05-06T08:01:26.000Z" in text


def test_every_command_takes_quiet_and_json():
    """-q/--quiet and --json on every command (what a script passes to any of them)."""
    from tollcli.cli.app import COMMANDS

    names = [n for n in COMMANDS if n != "geoobjects"] + [f"geoobjects {s}" for s in ("build", "check", "info", "compile")]
    for name in names:
        proc = run_cli(*name.split(), "--help")
        text = proc.stdout.decode()
        assert proc.returncode == 0 and "--quiet" in text and "--json" in text, name


def test_the_parsers_choices_are_the_rooms_own():
    """The choices the parser checks (cli/options.py) are the tuples the rooms below accept, and a value outside them is a
    usage error in one line, naming the choices."""
    from tollcli.cli import options as opt
    from tollcli.gnss.sigma_models import SIGMA_MODELS
    from tollcli.integrity.environment import ENVIRONMENTS
    from tollcli.integrity.raim import MODES
    from tollcli.integrity.sources import LEVEL_CHOICES
    from tollcli.integrity.trajectory import POSITIONINGS
    from tollcli.integrity.verdict import POLICIES
    from tollcli.io.sources import INPUT_KINDS

    assert opt.RAIM_MODES == MODES and opt.ENVIRONMENTS == ENVIRONMENTS and opt.INTEGRITY_LEVELS == LEVEL_CHOICES
    assert opt.SIGMA_MODELS == SIGMA_MODELS and opt.INPUT_KINDS == INPUT_KINDS and opt.POLICIES == tuple(POLICIES)
    assert opt.POSITIONINGS == POSITIONINGS
    proc = run_cli("integrity", SAMPLE, "--raim", "raimy", "-o", "-")
    assert proc.returncode == 2 and proc.stderr.decode().count("\n") == 1
    assert "'raimy' is not one of 'ss', 'etc', 'classic'" in proc.stderr.decode() and "Value error" not in proc.stderr.decode()
