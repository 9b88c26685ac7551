"""``tollcli epochs`` as a user runs it: outputs, pipes, errors and exit codes."""

from __future__ import annotations

import gzip
import io
import json

import pandas as pd
import pytest
from conftest import SAMPLES, run_cli, shared

from tollcli import __version__
from tollcli.readers.nmea import compose

SAMPLE = str(SAMPLES / "straight-drive.nmea")


def _one_error_line(proc, code: int, *needles: str) -> str:
    err = proc.stderr.decode()
    assert proc.returncode == code, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0]
    return lines[0]


def test_version_and_help():
    proc = run_cli("--version")
    assert proc.returncode == 0 and proc.stdout.decode().strip() == f"tollcli {__version__}"
    for args in (["--help"], ["epochs", "--help"]):
        proc = run_cli(*args)
        assert proc.returncode == 0
        assert "Exit codes" in proc.stdout.decode()


def test_sample_to_csv_on_stdout_reports_skips():
    proc = run_cli("epochs", SAMPLE)
    assert proc.returncode == 0
    table = pd.read_csv(io.BytesIO(proc.stdout))
    assert len(table) == 180
    assert table["time_utc"].iloc[0] == "2024-05-06T08:00:00.000Z"
    assert "180 epochs" in proc.stderr.decode() and "1 bad checksum" in proc.stderr.decode()


def test_formats_round_trip(tmp_path):
    outs = {ext: tmp_path / f"e.{ext}" for ext in ("csv", "parquet", "geojson", "json")}
    for path in outs.values():
        assert run_cli("epochs", SAMPLE, "-o", str(path), "-q").returncode == 0
    csv = pd.read_csv(outs["csv"], dtype={"lat_deg": str})
    assert csv["lat_deg"].iloc[0] == "42.6987"  # the log's 4241.9220000, as written: no 42.698699999999995
    csv["lat_deg"] = csv["lat_deg"].map(float)
    parquet = pd.read_parquet(outs["parquet"])
    assert parquet["lat_deg"].iloc[0] != 42.6987  # the double (42 + 41.922/60) is a bit off; Parquet keeps it
    assert str(parquet["time_utc"].dtype) == "datetime64[ms, UTC]"
    # CSV: 15 significant digits, the double's decimal (every decimal of ≤ 15 digits comes back as written)
    pd.testing.assert_series_equal(csv["lat_deg"], parquet["lat_deg"].map(lambda v: float(f"{v:.15g}")), check_exact=True)
    assert (csv["lat_deg"] - parquet["lat_deg"]).abs().max() <= 1e-14 * 90
    geo = json.loads(outs["geojson"].read_text())
    assert geo["type"] == "FeatureCollection" and len(geo["features"]) == 180
    first = geo["features"][0]
    assert first["geometry"]["coordinates"] == [parquet["lon_deg"].iloc[0], parquet["lat_deg"].iloc[0]]
    rows = json.loads(outs["json"].read_text())
    assert len(rows) == 180 and rows[0]["gbs_p_md"] is None and rows[0]["time_utc"] == "2024-05-06T08:00:00.000Z"


def test_satellite_table_and_json_summary(tmp_path):
    proc = run_cli("epochs", SAMPLE, "-o", str(tmp_path / "e.csv"), "--satellites", str(tmp_path / "s.parquet"), "--json")
    assert proc.returncode == 0
    summary = json.loads(proc.stdout)
    assert summary["epochs"] == 180 and summary["bad_checksum"] == 1 and summary["skipped"] == 1
    sats = pd.read_parquet(tmp_path / "s.parquet")
    assert len(sats) == 180 * 11 and set(sats.constellation) == {"GPS", "Galileo"}


def test_stdin_and_gzip_give_the_same_table(tmp_path):
    data = open(SAMPLE, "rb").read()
    gz = tmp_path / "drive.nmea.gz"
    gz.write_bytes(gzip.compress(data))
    plain = run_cli("epochs", SAMPLE, "-q").stdout
    assert run_cli("epochs", "-", "-q", stdin=data).stdout == plain
    assert run_cli("epochs", str(gz), "-q").stdout == plain


def test_outputs_are_deterministic(tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    run_cli("epochs", SAMPLE, "-o", str(a), "-q")
    run_cli("epochs", SAMPLE, "-o", str(b), "-q")
    assert a.read_bytes() == b.read_bytes()


def test_missing_file_is_a_usage_error():
    _one_error_line(run_cli("epochs", "no-such-log.nmea"), 2, "no-such-log.nmea", "no such file")


def test_directory_is_a_usage_error(tmp_path):
    _one_error_line(run_cli("epochs", str(tmp_path)), 2, "is a directory")


def test_unknown_output_extension_is_a_usage_error(tmp_path):
    _one_error_line(run_cli("epochs", SAMPLE, "-o", str(tmp_path / "x.xlsx")), 2, "unknown output format")


def test_empty_file_is_a_data_error(tmp_path):
    empty = tmp_path / "empty.nmea"
    empty.write_bytes(b"")
    _one_error_line(run_cli("epochs", str(empty)), 1, "empty.nmea", "empty file")


def test_non_nmea_file_is_a_data_error():
    _one_error_line(run_cli("epochs", "pyproject.toml"), 1, "pyproject.toml", "no NMEA sentences")


def test_binary_only_gpsd_log_is_a_data_error():
    log = shared("gpsd", "rtcm3.log")
    _one_error_line(run_cli("epochs", str(log)), 1, "rtcm3.log")


def test_strict_fails_on_the_damaged_line_and_keeps_the_old_output(tmp_path):
    out = tmp_path / "epochs.csv"
    out.write_text("previous run\n")
    line = _one_error_line(run_cli("epochs", SAMPLE, "--strict", "-o", str(out)), 1)
    assert line.endswith("straight-drive.nmea:103: bad checksum (*00 given, 1E computed)")
    assert out.read_text() == "previous run\n"  # nothing half-written, old file intact
    assert [p.name for p in tmp_path.iterdir()] == ["epochs.csv"]  # no temporary left behind


def test_log_without_dates_needs_date_option(tmp_path):
    log = tmp_path / "gga-only.nmea"
    log.write_text("\n".join(compose.gga(t, 45.0, 7.0) for t in (3600.0, 3601.0)) + "\n")
    proc = run_cli("epochs", str(log))
    assert proc.returncode == 0 and "without a date" in proc.stderr.decode()
    proc = run_cli("epochs", str(log), "--date", "2020-02-29", "-q")
    assert pd.read_csv(io.BytesIO(proc.stdout))["time_utc"].tolist() == ["2020-02-29T01:00:00.000Z", "2020-02-29T01:00:01.000Z"]
    _one_error_line(run_cli("epochs", str(log), "--date", "29/02/2020"), 2)


@pytest.mark.parametrize("args", [["epochs", SAMPLE, "--json"], ["epochs", SAMPLE, "-o", "-", "--satellites", "-"]])
def test_conflicting_stdout_uses_are_usage_errors(args):
    _one_error_line(run_cli(*args), 2)


def test_a_pseudorange_log_gives_the_positions_its_pseudoranges_solve_to(tmp_path):
    """The real Berlin drive (libRSF): an epoch per epoch, the snapshot WLS positions `integrity --positioning snapshot`
    vouches for (the same numbers), and a satellite row per pseudorange used, its angles and σ sensible."""
    log = str(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt"))
    epochs, satellites, checked = tmp_path / "e.csv", tmp_path / "s.parquet", tmp_path / "i.csv"
    proc = run_cli("epochs", log, "-o", str(epochs), "--satellites", str(satellites), "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    summary = json.loads(proc.stdout)
    assert (summary["format"], summary["epochs"], summary["fixes"], summary["skipped_lines"]) == ("librsf", 1372, 1372, 0)
    table, sats = pd.read_csv(epochs), pd.read_parquet(satellites)
    assert len(table) == 1372 and len(sats) == summary["pseudoranges"] == table["n_measurements"].sum()
    assert sats.groupby("epoch").size().to_numpy().tolist() == table["n_measurements"].tolist()
    assert sats["elev_deg"].between(-5, 90).all() and sats["azim_deg"].between(0, 360).all() and (sats["sigma_m"] > 0).all()
    assert set(sats["sv"].str[0]) == {"G", "E"} and set(sats["clock_group"]) == {0, 1}
    proc = run_cli("integrity", log, "--positioning", "snapshot", "-q", "-o", str(checked))
    assert proc.returncode == 0, proc.stderr.decode()
    vouched = pd.read_csv(checked)
    for column in ("lat_deg", "lon_deg", "height_m"):
        assert (table[column] == vouched[column]).all(), column


@pytest.mark.parametrize("name", ["pixel6_gnsslogger.txt", "pixel6.23o"])
@pytest.mark.parametrize("command", ["epochs", "integrity"])
def test_a_pseudorange_log_without_its_orbits_says_which_to_give(tmp_path, name, command):
    """A GnssLogger file and a RINEX observation file carry no orbits: one line naming the file and --nav, exit 2."""
    log = shared("android", name)
    _one_error_line(run_cli(command, str(log), "-o", str(tmp_path / "e.csv")), 2, str(log) + ":", "no satellite orbits", "--nav")
    assert not (tmp_path / "e.csv").exists()


def test_a_malformed_pseudorange_line_is_counted_and_strict_refuses_it(tmp_path):
    lines = shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt").read_text().splitlines()[:2000]
    bad = tmp_path / "bad.txt"
    bad.write_text("\n".join([*lines[:50], "pseudorange3 1.5 not-a-number 25 1 2 3 4 1 40 40", *lines[50:]]) + "\n")
    proc = run_cli("epochs", str(bad), "-o", str(tmp_path / "e.csv"))
    assert proc.returncode == 0 and "skipped 1 malformed lines" in proc.stderr.decode()
    proc = run_cli("epochs", str(bad), "-o", str(tmp_path / "e.csv"), "--max-bad", "0")
    assert proc.returncode == 3 and (tmp_path / "e.csv").exists()
    _one_error_line(run_cli("epochs", str(bad), "--strict", "-o", str(tmp_path / "f.csv")), 1, "bad.txt:51")


def test_a_rawx_log_without_orbits_gives_its_receivers_own_fixes(tmp_path):
    """gpsd's NEO-M8T log has RXM-RAWX pseudoranges but no navigation data: its NAV fixes are read instead, and the
    messages name the log (not the copy it was read through)."""
    out = tmp_path / "e.csv"
    proc = run_cli("epochs", str(shared("gpsd", "ublox-neo-m8t.log")), "-o", str(out))
    err = proc.stderr.decode()
    assert proc.returncode == 0, err
    assert "ublox-neo-m8t.log: no orbits to solve its pseudoranges" in err and "receiver's own fixes" in err
    assert "ublox-neo-m8t.log: 243 lines, 242 UBX messages" in err and "tollcli-log-" not in err
    assert "skipped 1 lines (1 malformed)" in err  # its last frame, cut short by the end of the file
    assert len(pd.read_csv(out)) == 39


@pytest.mark.parametrize("command", ["epochs", "integrity"])
def test_a_rinex_navigation_file_given_as_the_log_says_what_it_is(tmp_path, command):
    """The IGS broadcast file is orbits, not observations: it goes with --nav (it said "an observation file carries no
    orbits: give --nav", of the file that was the orbits)."""
    log = shared("rinex", "brdc1190.21n")
    _one_error_line(run_cli(command, str(log), "-o", str(tmp_path / "e.csv")), 2, str(log) + ":", "RINEX navigation file",
                    "--nav beside the observation file")  # fmt: skip
