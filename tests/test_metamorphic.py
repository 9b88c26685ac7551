"""Metamorphic tests: changes to the input that must not change the invoice (or change it only where they touch).

They run over the bundled samples and simulated drives; each says what it changes and what must hold.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tollcli.integrity.speed import SpeedParams, speed_integrity
from tollcli.job.pipeline import ChargeSettings, charge_log
from tollcli.readers.nmea.fields import checksum

ROOT = Path(__file__).resolve().parents[1]
GEO = str(ROOT / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(ROOT / "geoobjects" / "example-tariff.toml")
SIM = sorted((ROOT / "samples" / "sim").glob("*/drive.nmea"))


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


def _blank_speed(line: str) -> str:
    """The same RMC or VTG sentence with its speed fields empty (a receiver that has no speed for that epoch)."""
    body = line.strip()[1 : line.strip().rfind("*")]
    f = body.split(",")
    if f[0].endswith("RMC"):
        f[7] = ""
    elif f[0].endswith("VTG"):
        f[5] = f[7] = ""
    return _sentence(",".join(f))


def _charge(log: Path, **settings) -> dict:
    invoice, _ = charge_log(str(log), GEO, TARIFF, ChargeSettings(**settings))
    return invoice


def _lines_by_object(invoice: dict) -> dict[str, dict]:
    return {line["geoobject"]: {k: v for k, v in line.items()} for line in invoice["lines"]}


# ---------------------------------------------------------------- one epoch without speed (issue: NaN poisons windows)
def test_a_missing_speed_only_touches_the_windows_it_is_in():
    """Speed integrity over a table with one missing speed equals the intact one outside the N + 1 windows holding it."""
    n = SpeedParams().window_intervals
    rng = np.random.default_rng(7)
    k = 300
    t = pd.date_range("2026-03-02 08:00", periods=k, freq="1s", tz="UTC")
    speed = 25 + np.cumsum(rng.normal(0, 0.05, k))
    north_m = np.cumsum(speed)
    table = pd.DataFrame({"time_utc": t, "speed_mps": speed, "lat_deg": 42.7 + north_m / 111_195.0,
                          "lon_deg": np.full(k, 2.9)})  # fmt: skip
    intact = speed_integrity(table)
    for gap in (0, 37, 150, k - 1):
        holed = table.copy()
        holed.loc[gap, "speed_mps"] = np.nan
        out = speed_integrity(holed)
        touched = np.zeros(k, bool)
        touched[gap : gap + n + 1] = True
        pd.testing.assert_frame_equal(out[~touched].reset_index(drop=True), intact[~touched].reset_index(drop=True))
        assert (out.loc[touched, "speed_status"] == "no_data").all()


@pytest.mark.parametrize("log", SIM, ids=lambda p: p.parent.name)
def test_an_epoch_without_speed_changes_no_passage_it_is_not_in(tmp_path, log):
    """RMC and VTG of one early epoch lose their speed: later passages are charged exactly as before."""
    lines = log.read_text().splitlines()
    rmc = [i for i, line in enumerate(lines) if line[3:6] == "RMC"]
    at = rmc[4]  # the fifth epoch, in the first geo-object
    vtg = next(i for i in range(at, len(lines)) if lines[i][3:6] == "VTG")
    lines[at], lines[vtg] = _blank_speed(lines[at]), _blank_speed(lines[vtg])
    holed = tmp_path / "drive.nmea"
    holed.write_text("\n".join(lines) + "\n")
    before, after = _charge(log), _charge(holed)
    assert before["parameters"]["policy_used"] == after["parameters"]["policy_used"] == "raim+speed"
    first_exit = min(line["exit_utc"] for line in before["lines"])
    later = {g: line for g, line in _lines_by_object(before).items() if line["entry_utc"] > first_exit}
    assert later, "the drive has passages after the first one"
    got = _lines_by_object(after)
    for g, line in later.items():
        assert got.get(g) == line


# ---------------------------------------------------------------- line endings (issue: a CR-only log read as one line)
from conftest import SHARED_DATA  # noqa: E402
from tollcli.readers.nmea import ReadStats, read_nmea  # noqa: E402

GPSD = SHARED_DATA / "gpsd"


def _text_lines(path: Path) -> list[bytes] | None:
    """The log's lines when it is all text (sentences, comments, blanks), else None (binary protocols mixed in)."""
    lines = path.read_bytes().replace(b"\r\n", b"\n").split(b"\n")
    if any(line and line[:1] not in b"$!#" or b"\r" in line for line in lines):
        return None
    return lines


def _text_logs() -> list[Path]:
    logs = [ROOT / "samples" / "straight-drive.nmea", *SIM]
    if GPSD.exists():
        logs += [p for p in sorted(GPSD.glob("*.log")) if _text_lines(p) is not None]
    return logs


def _tables(data: bytes, tmp_path: Path, name: str):
    path = tmp_path / name
    path.write_bytes(data)
    stats = ReadStats()
    tables = read_nmea(str(path), stats=stats, block_bytes=4096)
    counts = {k: v for k, v in stats.as_dict().items() if k != "source"}
    return tables, counts


def test_text_logs_cover_the_real_receivers():
    if not GPSD.exists():
        pytest.skip("real data not available: ../shared/data/gpsd")
    assert len(_text_logs()) >= 40


@pytest.mark.parametrize("log", _text_logs(), ids=lambda p: p.name)
def test_every_line_ending_gives_the_same_tables(tmp_path, log):
    """LF, CR LF, CR alone and a mix of the three: the same epochs, satellites and counts (line numbers too)."""
    lines = _text_lines(log)
    if lines and lines[-1] == b"":
        lines = lines[:-1]
    reference, counts = _tables(b"\n".join(lines) + b"\n", tmp_path, "lf.nmea")
    # mixed: never a CR right before a blank line ended by CR LF — CR CR LF is one line end (some receivers write it)
    ends = {"crlf": [b"\r\n"], "cr": [b"\r"], "mixed": [b"\r", b"\n", b"\r\n", b"\n"]}
    for kind, cycle in ends.items():
        data = b"".join(line + cycle[i % len(cycle)] for i, line in enumerate(lines))
        tables, got = _tables(data, tmp_path, f"{kind}.nmea")
        assert got == counts, kind
        pd.testing.assert_frame_equal(tables.epochs, reference.epochs, obj=f"{kind} epochs")
        pd.testing.assert_frame_equal(tables.satellites, reference.satellites, obj=f"{kind} satellites")


@pytest.mark.parametrize("log", SIM[:2], ids=lambda p: p.parent.name)
def test_a_cr_log_is_charged_as_the_lf_log(tmp_path, log):
    cr = tmp_path / "drive-cr.nmea"
    cr.write_bytes(log.read_bytes().replace(b"\n", b"\r"))
    before, after = _charge(log), _charge(cr)
    assert after["lines"] and [line["fee"] for line in after["lines"]] == [line["fee"] for line in before["lines"]]
    assert after["total"] == before["total"]
