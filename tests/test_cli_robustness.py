"""The CLI as users meet it in shells: closed pipes, broken compressed files — documented exit codes, one line, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def test_a_reader_that_stops_early_is_not_an_error(tmp_path):
    """`tollcli epochs LOG | head`: exit 0 and nothing on stderr once head has what it wants."""
    log = tmp_path / "long.nmea"
    log.write_bytes(b"".join((SAMPLES / "sim" / d / "drive.nmea").read_bytes() for d in ("rural-clean", "urban-clean") * 4))
    proc = subprocess.Popen([sys.executable, "-m", "tollcli", "epochs", str(log), "-q"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=dict(os.environ, NO_COLOR="1"))  # fmt: skip
    assert proc.stdout.read(100)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert err == ""


@pytest.mark.parametrize("content", [b"\x1f\x8b", b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03"], ids=["magic", "header"])
@pytest.mark.parametrize("command", ["process", "findings", "integrity", "epochs", "locate"])
def test_a_gzip_that_is_only_a_header_is_a_data_error(tmp_path, content, command):
    log = tmp_path / "day.nmea.gz"
    log.write_bytes(content)
    extra = {"process": ["--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "i.json")], "findings": ["--geo", GEO]}
    result = run_cli(command, str(log), *extra.get(command, []))
    err = result.stderr.decode()
    assert result.returncode == 1, err
    assert "interrupted" not in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "day.nmea.gz" in err


# ---------------------------------------------------------------- what users get wrong: one line, a documented code
DRIVE = str(SAMPLES / "sim" / "rural-clean" / "drive.nmea")


def _one_line(result, code: int) -> str:
    err = result.stderr.decode()
    assert result.returncode == code, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("command", [["simulate"], ["batch", DRIVE, "--geo", GEO, "--tariff", TARIFF]], ids=["simulate", "batch"])
def test_an_existing_file_as_output_folder_is_a_usage_error(tmp_path, command):
    existing = tmp_path / "already.txt"
    existing.write_text("keep me\n")
    assert "is a file" in _one_line(run_cli(*command, "-o", str(existing), "-q"), 2)
    assert existing.read_text() == "keep me\n"


def test_an_output_the_system_refuses_is_a_system_error_naming_it():
    err = _one_line(run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", "/proc/invoice.json"), 4)
    assert "/proc/invoice.json" in err


def test_a_deeply_nested_json_is_a_data_error(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000)
    assert "nested too deeply" in _one_line(run_cli("verify", str(deep)), 1)
    deep_feature = tmp_path / "deep.geojson"  # a geo-object file is read feature by feature: nested in a feature
    deep_feature.write_text('{"type": "FeatureCollection", "features": [' + "[" * 100_000)
    assert "nested too deeply" in _one_line(run_cli("process", DRIVE, "--geo", str(deep_feature), "--tariff", TARIFF, "-q", "-o", "-"), 1)
    assert "not a GeoJSON FeatureCollection" in _one_line(run_cli("process", DRIVE, "--geo", str(deep), "--tariff", TARIFF, "-q", "-o", "-"), 1)


def test_an_unknown_metric_crs_in_a_geo_object_file_is_refused(tmp_path):
    import json

    geo = json.loads(open(GEO).read())
    for f in geo["features"]:
        f["properties"]["crs_metric"] = "EPSG:999999"
    path = tmp_path / "geo.geojson"
    path.write_text(json.dumps(geo))
    assert "EPSG:999999" in _one_line(run_cli("process", DRIVE, "--geo", str(path), "--tariff", TARIFF, "-q", "-o", "-"), 1)


def test_a_file_name_that_is_not_utf8_is_recorded_printably(tmp_path):
    import json

    name = os.fsdecode(b"dr\xffive.nmea")
    log = os.path.join(str(tmp_path), name)
    with open(log, "wb") as fh:
        fh.write(open(DRIVE, "rb").read())
    result = run_cli("process", log, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", "-")
    assert result.returncode == 0, result.stderr.decode()
    invoice = json.loads(result.stdout)
    assert invoice["inputs"]["log"].endswith("dr\\xffive.nmea") and invoice["lines"]


def test_a_damaged_compiled_copy_of_the_geo_objects_is_made_again(tmp_path):
    env_cache = tmp_path / "cache"
    env = dict(os.environ, TOLLCLI_CACHE_DIR=str(env_cache), NO_COLOR="1")
    run = lambda out: subprocess.run([sys.executable, "-m", "tollcli", "process", DRIVE, "--geo", GEO, "--tariff", TARIFF,  # noqa: E731
                                      "-q", "-o", str(tmp_path / out)], capture_output=True, env=env, timeout=300)  # fmt: skip
    assert run("a.json").returncode == 0
    for cached in env_cache.rglob("*.np*"):
        cached.write_bytes(cached.read_bytes()[:100])
    again = run("b.json")
    assert again.returncode == 0, again.stderr.decode()
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_a_defect_is_one_line_with_its_own_exit_code(monkeypatch, capsys):
    import tollcli.cli.process as process_command  # imported before the patch: it binds charge_log at import
    from tollcli.cli import main as entry

    def broken(*args, **kwargs):
        raise ZeroDivisionError("planted")

    monkeypatch.delenv("TOLLCLI_DEBUG", raising=False)
    monkeypatch.setattr(process_command, "charge_log", broken)
    with pytest.raises(SystemExit) as exit_:
        entry.main(["process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", "-"])
    assert exit_.value.code == 5
    err = capsys.readouterr().err
    assert "internal error (ZeroDivisionError: planted)" in err and len(err.strip().splitlines()) == 1


def test_sigterm_leaves_no_temporary_file_and_no_half_output(tmp_path):
    """SIGTERM while `epochs -o out.csv` writes: exit 143, no .tmp left, no out.csv (15 tries at different moments)."""
    import signal
    import time

    log = tmp_path / "long.nmea"
    log.write_bytes(b"".join((SAMPLES / "sim" / d / "drive.nmea").read_bytes() for d in ("rural-clean", "urban-clean") * 10))
    out = tmp_path / "out" / "epochs.csv"
    out.parent.mkdir()
    for attempt in range(15):
        proc = subprocess.Popen([sys.executable, "-m", "tollcli", "epochs", str(log), "-q", "-o", str(out),
                                 "--satellites", str(out.parent / "sats.parquet")],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not list(out.parent.glob(".*.tmp")) and proc.poll() is None:
            time.sleep(0.002)
        time.sleep(0.01 * (attempt % 5))
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=60)
        leftovers = list(out.parent.glob(".*.tmp"))
        assert not leftovers, (attempt, code, leftovers, proc.stderr.read())
        if code == 0:  # finished before the signal: a whole output
            out.unlink()
            (out.parent / "sats.parquet").unlink()
            continue
        assert code == 143 and not out.exists(), (attempt, code, proc.stderr.read())


@pytest.mark.parametrize("command", [["findings", DRIVE, "--geo", GEO], ["audit", "INVOICE"],
                                     ["geoobjects", "build", str(REPO / "geoobjects" / "example-roads.geojson")],
                                     ["process", DRIVE, "--geo", GEO, "--tariff", TARIFF]], ids=lambda c: c[0] + c[1][:5])  # fmt: skip
def test_an_output_extension_a_command_does_not_write_is_refused(tmp_path, command):
    if command[1] == "INVOICE":
        invoice = tmp_path / "inv.json"
        assert run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice)).returncode == 0
        command = ["audit", str(invoice)]
    out = tmp_path / "out.parquet"
    err = _one_line(run_cli(*command, "-q", "-o", str(out)), 2)
    assert "out.parquet" in err and not out.exists()


@pytest.mark.parametrize("command", [["integrity"], ["locate"], ["findings", "--geo", GEO]], ids=lambda c: c[0])
def test_the_date_the_reader_asks_for_is_an_option_of_the_command(tmp_path, command):
    """A GGA-only log has no date; the hint says --date, and integrity, locate and findings take it."""
    gga = tmp_path / "gga.nmea"
    gga.write_text("".join(line for line in (SAMPLES / "straight-drive.nmea").read_text().splitlines(True) if line[3:6] == "GGA"))
    out = tmp_path / ("out.json" if command[0] == "findings" else "out.csv")
    hint = run_cli("integrity", str(gga), "-o", str(tmp_path / "hint.csv")).stderr.decode()
    assert "--date" in hint
    result = run_cli(command[0], str(gga), *command[1:], "--date", "2024-05-06", "-o", str(out))
    assert result.returncode == 0, result.stderr.decode()
    assert "2024-05-06" in out.read_text() or command[0] == "findings"
