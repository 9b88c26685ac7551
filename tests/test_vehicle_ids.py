"""Vehicle ids from a log's ``# vehicle:`` header (part of issue 55): the whole rest of the line is the id — three logs
headed ``FLEET 1``, ``FLEET 2`` and ``FLEET 3`` were one vehicle ``FLEET`` and ``batch`` priced the later passages as
``continued`` at 0.00 —, an empty header is no id (it took the next line's first token, ``#``), and an id with
control characters or too long for a folder name fails its log with the reason (300 characters: ``internal error
(OSError: File name too long)``)."""

from __future__ import annotations

import json

from conftest import REPO, SAMPLES, run_cli

from tollcli.enforcement.locate import VEHICLE_ID_MAX_CHARS, vehicle_id_problem, vehicle_in_head

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def test_the_header_id_is_the_whole_line():
    assert vehicle_in_head(b"# vehicle: FLEET 1\n$GPGGA,...") == "FLEET 1"
    assert vehicle_in_head(b"# Vehicle_ID =  TRK-042  \r\n") == "TRK-042"
    assert vehicle_in_head(b"# vehicle:\n# other: z\n") is None  # not the next line's '#'
    assert vehicle_in_head(b"# vehicle: x\ty\n") == "x\ty" and vehicle_id_problem("x\ty")
    assert vehicle_id_problem("A" * (VEHICLE_ID_MAX_CHARS + 1)) and vehicle_id_problem("Ä" * VEHICLE_ID_MAX_CHARS) is None


def _batch(tmp_path, headers: dict[str, str]):
    logs = tmp_path / "logs"
    logs.mkdir()
    drive = (SAMPLES / "straight-drive.nmea").read_text()
    for name, header in headers.items():
        (logs / f"{name}.nmea").write_text(header + drive)
    out = tmp_path / "out"
    done = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "-q")
    return done, json.loads((out / "summary.json").read_text())


def test_three_fleet_vehicles_are_three(tmp_path):
    done, summary = _batch(tmp_path, {f"log{i}": f"# vehicle: FLEET {i}\n" for i in (1, 2, 3)})
    assert done.returncode == 0, done.stderr.decode()
    single = json.loads(next((tmp_path / "out" / "invoices").rglob("*.json")).read_text())["total"]
    assert single != "0.00"
    assert sorted((o["vehicle"], o["total"]) for o in summary["outcomes"]) == [(f"FLEET {i}", single) for i in (1, 2, 3)]


def test_an_impossible_id_fails_its_log_and_only_it(tmp_path):
    done, summary = _batch(tmp_path, {"tab": "# vehicle: x\ty\n", "long": f"# vehicle: {'A' * 300}\n", "empty": "# vehicle:\n# z\n"})
    err = done.stderr.decode()
    assert done.returncode == 6 and "internal error" not in err and len(err.strip().splitlines()) == 1, err
    by_log = {o["log"].rsplit("/", 1)[-1]: o for o in summary["outcomes"]}
    assert by_log["empty.nmea"]["status"] == "done" and by_log["empty.nmea"]["vehicle"] == "empty"  # the file name
    assert "control characters" in by_log["tab.nmea"]["error"] and "300 characters" in by_log["long.nmea"]["error"]


def test_three_consecutive_fleet_logs_are_charged_each_as_its_own(tmp_path):
    """The issue's case: one drive cut into three consecutive logs headed ``FLEET 1``, ``FLEET 2``, ``FLEET 3`` — three
    vehicles. Read as one vehicle ``FLEET``, batch priced the later passages as ``continued`` at 0.00; now the batch
    total is the sum of each log charged alone."""
    lines = (SAMPLES / "straight-drive.nmea").read_text().splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith("$GNRMC")]
    cuts = [0, starts[len(starts) // 3], starts[2 * len(starts) // 3], len(lines)]
    logs = tmp_path / "logs"
    logs.mkdir()
    alone = []
    for k in range(3):
        path = logs / f"part{k + 1}.nmea"
        path.write_text(f"# vehicle: FLEET {k + 1}\n" + "\n".join(lines[cuts[k] : cuts[k + 1]]) + "\n")
        out = tmp_path / f"alone{k}.json"
        assert run_cli("process", str(path), "--geo", GEO, "--tariff", TARIFF, "-o", str(out), "-q").returncode == 0
        alone.append(json.loads(out.read_text())["total"])
    done = run_cli("batch", str(logs), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "out"), "-q")
    assert done.returncode == 0, done.stderr.decode()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted((o["vehicle"], o["total"]) for o in summary["outcomes"]) == [(f"FLEET {k + 1}", alone[k]) for k in range(3)]
    assert sum(float(t) for t in alone) > 0
