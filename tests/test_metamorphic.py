"""Metamorphic tests: changes to the input that must not change the invoice (or change it only where they touch).

They run over the bundled samples and simulated drives; each says what it changes and what must hold.
"""

from __future__ import annotations

import json
from decimal import Decimal
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
    n = SpeedParams().intervals(1.0)
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


# ---------------------------------------------------------------- a 20 s signal gap (tunnel) anywhere
def _epochs_of(lines: list[str]) -> list[list[str]]:
    """The log's lines grouped by epoch (an epoch starts at its RMC)."""
    groups: list[list[str]] = []
    for line in lines:
        if line[3:6] == "RMC" or not groups:
            groups.append([])
        groups[-1].append(line)
    return groups


def _passages_away_from(invoice: dict, start_utc: str, end_utc: str, margin_s: float) -> dict[tuple, dict]:
    """Charged and uncharged passages whose time span stays ``margin_s`` away from [start, end]."""
    lo, hi = pd.Timestamp(start_utc) - pd.Timedelta(seconds=margin_s), pd.Timestamp(end_utc) + pd.Timedelta(seconds=margin_s)
    out = {}
    for kind in ("lines", "not_charged"):
        for p in invoice[kind]:
            if pd.Timestamp(p["exit_utc"]) < lo or pd.Timestamp(p["entry_utc"]) > hi:
                out[(kind, p["geoobject"], p["entry_utc"])] = _without_row_numbers(p)
    return out


def _without_row_numbers(value):
    """Evidence without epoch and line numbers (they shift when epochs are removed; times identify positions)."""
    if isinstance(value, dict):
        return {k: _without_row_numbers(v) for k, v in value.items() if k not in ("epoch", "line")}
    if isinstance(value, list):
        return [_without_row_numbers(v) for v in value]
    return value


@pytest.mark.parametrize("log", SIM, ids=lambda p: p.parent.name)
@pytest.mark.parametrize("at", [20, 75, 110, 160, 205])
@pytest.mark.parametrize("how", ["silent", "no_fix"])
def test_a_20s_gap_changes_only_the_passages_it_touches(tmp_path, log, at, how):
    """20 epochs without a fix (the receiver silent, or reporting no fix) change no passage more than the speed
    window (10 s) away from the gap."""
    groups = _epochs_of(log.read_text().splitlines())
    gap = groups[at : at + 20]
    t0, t1 = gap[0][0].split(",")[1], gap[-1][0].split(",")[1]
    day = "2026-03-02T"
    start_utc, end_utc = f"{day}{t0[:2]}:{t0[2:4]}:{t0[4:]}Z", f"{day}{t1[:2]}:{t1[2:4]}:{t1[4:]}Z"
    if how == "silent":
        kept = groups[:at] + groups[at + 20 :]
    else:
        kept = groups[:at] + [[_no_fix(line) for line in g] for g in gap] + groups[at + 20 :]
    holed = tmp_path / "drive.nmea"
    holed.write_text("\n".join(line for g in kept for line in g) + "\n")
    before, after = _charge(log), _charge(holed)
    margin = SpeedParams().intervals(1.0) + 1
    untouched = _passages_away_from(before, start_utc, end_utc, margin)
    assert _passages_away_from(after, start_utc, end_utc, margin) == untouched


def _no_fix(line: str) -> str:
    """The same sentence saying 'no fix': RMC status V, GGA quality 0, no position, no speed."""
    body = line[1 : line.rfind("*")]
    f = body.split(",")
    kind = f[0][2:]
    if kind == "RMC":
        f[2], f[3], f[4], f[5], f[6], f[7], f[8] = "V", "", "", "", "", "", ""
        f[12:13] = ["N"] if len(f) > 12 else []
    elif kind == "GGA":
        f[2:7] = ["", "", "", "", "0"]
        f[7] = "00"
    elif kind == "VTG":
        f[1:] = ["", "T", "", "M", "", "N", "", "K", "N"][: len(f) - 1]
    elif kind in ("GSA", "GSV", "GST", "GRS"):
        return ""
    else:
        return line
    body = ",".join(f)
    return _sentence(body)


# ---------------------------------------------------------------- a log split in two files
def _split(log: Path, tmp_path: Path, at: int) -> list[Path]:
    groups = _epochs_of(log.read_text().splitlines())
    parts = [tmp_path / "part1" / "TRK-1.nmea", tmp_path / "part2" / "TRK-1.nmea"]
    for part, chunk in zip(parts, (groups[:at], groups[at:])):
        part.parent.mkdir()
        part.write_text("\n".join(line for g in chunk for line in g) + "\n")
    return parts


def _charges(invoices: list[dict]) -> list[tuple]:
    return sorted((line["geoobject"], line["entry_utc"], line["exit_utc"], line["fee"]) for inv in invoices for line in inv["lines"])


@pytest.mark.parametrize("log", SIM, ids=lambda p: p.parent.name)
def test_a_log_split_between_passages_is_charged_as_the_whole_log(tmp_path, log):
    """The log cut into two files between two passages and charged as a batch: the whole log's charges."""
    from tollcli.job.batch import run_batch

    whole = _charge(log)
    first_exit = pd.Timestamp(min(line["exit_utc"] for line in whole["lines"]))
    groups = _epochs_of(log.read_text().splitlines())
    times = [pd.Timestamp(f"2026-03-02T{g[0].split(',')[1][:2]}:{g[0].split(',')[1][2:4]}:{g[0].split(',')[1][4:]}Z") for g in groups]
    at = next(i for i, t in enumerate(times) if t > first_exit + pd.Timedelta(seconds=2))
    parts = _split(log, tmp_path, at)
    out = tmp_path / "out"
    summary = run_batch([str(p) for p in parts], GEO, TARIFF, ChargeSettings(), str(out))
    assert summary["done"] == 2
    invoices = [json.loads(p.read_text()) for p in sorted((out / "invoices").rglob("*.json"))]
    assert _charges(invoices) == _charges([whole])
    assert summary["totals"] == {"EUR": whole["total"]}


@pytest.mark.parametrize("at", [60, 150])
def test_a_log_split_inside_a_passage_is_charged_once(tmp_path, at):
    """The log cut inside a passage into two files of one vehicle: the passage is charged once, by the invoice
    where it began; the next lists its part at fee 0 (``continued``). The second invoice verifies, and a rerun
    settles (both skipped, the same totals)."""
    from tollcli.job.batch import run_batch
    from tollcli.job.verify import verify_invoice

    log = SIM[0]
    whole = _charge(log)
    parts = _split(log, tmp_path, at)
    out = tmp_path / "out"
    summary = run_batch([str(p) for p in parts], GEO, TARIFF, ChargeSettings(), str(out))
    assert summary["totals"] == {"EUR": whole["total"]}
    invoices = [json.loads(p.read_text()) for p in sorted((out / "invoices").rglob("*.json"))]
    charged = sorted((line["geoobject"], line["entry_utc"], line["fee"]) for inv in invoices for line in inv["lines"]
                     if line["band"] != "continued")  # fmt: skip
    assert charged == sorted((line["geoobject"], line["entry_utc"], line["fee"]) for line in whole["lines"])
    continued = [(inv, line) for inv in invoices for line in inv["lines"] if line["band"] == "continued"]
    assert len(continued) == 1 and continued[0][1]["fee"] == "0.00"
    assert continued[0][1]["continues"]["log"] == str(parts[0]) and continued[0][0]["inputs"]["log"] == str(parts[1])
    assert continued[0][0]["parameters"]["continued"]
    for inv_path in sorted((out / "invoices").rglob("*.json")):
        verify_invoice(str(inv_path))
    again = run_batch([str(p) for p in parts], GEO, TARIFF, ChargeSettings(), str(out))
    assert again["skipped"] == 2 and again["totals"] == summary["totals"]


def test_logs_a_day_apart_are_not_joined(tmp_path):
    """The same vehicle's logs of two days: no passage is carried from one to the other."""
    from tollcli.job.batch import run_batch

    log = SIM[0]
    parts = _split(log, tmp_path, 60)
    parts[1].write_text("\n".join(_shift_rmc_date(line, 1) for line in parts[1].read_text().splitlines()) + "\n")
    summary = run_batch([str(p) for p in parts], GEO, TARIFF, ChargeSettings(), str(tmp_path / "out"))
    assert Decimal(summary["totals"]["EUR"]) > Decimal(_charge(log)["total"])  # the passage cut at 60 is charged twice
    invoices = [json.loads(p.read_text()) for p in sorted((tmp_path / "out" / "invoices").rglob("*.json"))]
    assert not any(line["band"] == "continued" for inv in invoices for line in inv["lines"])


# ---------------------------------------------------------------- RMC date jumps inside a continuous trip
def _shift_rmc_date(line: str, days: int) -> str:
    body = line[1 : line.rfind("*")]
    f = body.split(",")
    if f[0][2:] != "RMC" or not f[9]:
        return line
    date = (pd.Timestamp(f"20{f[9][4:6]}-{f[9][2:4]}-{f[9][0:2]}") + pd.Timedelta(days=days)).strftime("%d%m%y")
    f[9] = date
    return _sentence(",".join(f))


@pytest.mark.parametrize("how", ["one_day_once", "week_rollover_from_the_middle"])
def test_a_date_jump_inside_a_passage_charges_it_once_and_is_reported(tmp_path, how):
    """One RMC a day ahead in the middle of a passage, or every RMC from there on 1024 weeks back: the same
    charges (one passage, dated as the trip), and a ``date_jump`` finding where the date jumped."""
    log = SIM[0]
    before = _charge(log)
    first = before["lines"][0]
    middle = pd.Timestamp(first["entry_utc"]) + (pd.Timestamp(first["exit_utc"]) - pd.Timestamp(first["entry_utc"])) / 2
    groups = _epochs_of(log.read_text().splitlines())
    at = next(i for i, g in enumerate(groups) if g[0].split(",")[1][:6] >= middle.strftime("%H%M%S"))
    days, upto = (1, at + 1) if how == "one_day_once" else (-1024 * 7, len(groups))
    changed = groups[:at] + [[_shift_rmc_date(line, days) for line in g] for g in groups[at:upto]] + groups[upto:]
    jumped = tmp_path / "drive.nmea"
    jumped.write_text("\n".join(line for g in changed for line in g) + "\n")
    after = _charge(jumped)
    assert after["lines"] == before["lines"] and after["total"] == before["total"] and after["period"] == before["period"]
    found = [f for f in after["findings"]["items"] if f["kind"] == "date_jump"]
    assert len(found) == 1 and found[0]["evidence"]["given_minus_trip_days"] == days
    assert found[0]["evidence"]["week_rollover"] is (how != "one_day_once")
    assert found[0]["start_utc"].startswith(middle.strftime("%Y-%m-%dT%H:%M"))


# ---------------------------------------------------------------- inputs renamed and moved
def test_logs_renamed_and_moved_into_other_folders_give_the_same_invoices(tmp_path):
    """The same drives under other names, in other folders (two with the same name on two days): every log
    keeps an invoice of its own, and the charges do not depend on where a log lies or what it is called."""
    from tollcli.job.batch import run_batch

    def charges_of(out: Path) -> list[tuple]:
        docs = [json.loads(p.read_text()) for p in sorted((out / "invoices").rglob("*.json"))]
        return sorted((json.dumps(d["lines"], sort_keys=True), d["total"], d["period"]["start_utc"]) for d in docs)

    first = tmp_path / "first"
    first.mkdir()
    for log in SIM:
        (first / f"{log.parent.name}.nmea").write_bytes(log.read_bytes())
    a = run_batch(sorted(str(p) for p in first.iterdir()), GEO, TARIFF, ChargeSettings(vehicle="TRK-9"), str(tmp_path / "a"))
    moved = tmp_path / "moved"
    for i, log in enumerate(SIM):
        folder = moved / ("day1" if i % 2 else "day2") / "deep"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / ("TRK-9.nmea" if i < 2 else f"renamed-{i}.log")).write_bytes(log.read_bytes())
    b = run_batch(sorted(str(p) for p in moved.rglob("*.*")), GEO, TARIFF, ChargeSettings(vehicle="TRK-9"), str(tmp_path / "b"))
    assert a["done"] == b["done"] == len(SIM) and a["totals"] == b["totals"]
    assert a["overlapping"] == b["overlapping"] == len(SIM)  # three drives of one vehicle at the same hour: said
    assert len(list((tmp_path / "b" / "invoices").rglob("*.json"))) == len(SIM)
    assert charges_of(tmp_path / "a") == charges_of(tmp_path / "b")
