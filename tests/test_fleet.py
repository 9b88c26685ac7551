"""A mixed fleet in one batch: each vehicle charged by its own class and tariff attributes (``--fleet``)."""

from __future__ import annotations

import json
import shutil

import pytest

from conftest import REPO, run_cli
from tollcli.errors import DataError
from tollcli.job.fleet import read_fleet

TRUCK = REPO / "geoobjects" / "example-truck-tariff.toml"
GEO = REPO / "geoobjects" / "example-geoobjects.geojson"
ROADS = REPO / "geoobjects" / "example-roads.geojson"
HEADER = "vehicle,vehicle_class,weight_class,axles,euro_class,co2_class\n"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """One drive across the 1 July 2024 table change, as three vehicles' logs (the file name is the vehicle id)."""
    tmp = tmp_path_factory.mktemp("fleet")
    r = run_cli("simulate", "--route", str(ROADS), "--via", "A9-N1,A9-N2", "--geo", str(GEO), "--env", "rural", "--seed", "1",
                "--start-utc", "2024-06-30T21:58:30", "-o", str(tmp / "drive"), "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    folder = tmp / "logs"
    folder.mkdir()
    for vehicle in ("TRK-042", "TRK-043", "VAN-9"):
        shutil.copy(tmp / "drive" / "drive.nmea", folder / f"{vehicle}.nmea")
    return folder


def _batch(logs, fleet, out, *extra):
    r = run_cli("batch", str(logs), "--geo", str(GEO), "--tariff", str(TRUCK), "--fleet", str(fleet), "-o", str(out), "--json", *extra)
    outcomes = {o["vehicle"]: o for o in json.loads((out / "summary.json").read_text())["outcomes"]} if (out / "summary.json").exists() else {}
    return r, outcomes


def test_each_vehicle_is_charged_as_itself_and_an_unlisted_one_fails(logs, tmp_path):
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(HEADER + "TRK-042,truck,over-18t,5+,euro6,1\nTRK-043,truck,over-18t,4,euro6,1\n")
    out = tmp_path / "out"
    r, outcomes = _batch(logs, fleet, out, "--workers", "2")
    assert r.returncode == 6  # some logs failed, not all
    assert (outcomes["TRK-042"]["status"], outcomes["TRK-042"]["total"]) == ("done", "2.60")  # 0.51 + 2.09
    assert (outcomes["TRK-043"]["status"], outcomes["TRK-043"]["total"]) == ("done", "2.52")  # 4 axles: 0.47 + 2.05
    assert outcomes["VAN-9"]["status"] == "failed" and "'VAN-9' is not in the fleet file" in outcomes["VAN-9"]["error"]
    invoice = json.loads((out / "invoices" / "TRK-043" / "TRK-043.json").read_text())
    assert invoice["vehicle_class"] == "truck" and invoice["vehicle_attributes"]["axles"] == "4"
    assert run_cli("verify", str(out / "invoices" / "TRK-043" / "TRK-043.json")).returncode == 0
    # run again: both up to date; one vehicle's attributes change: only its log is redone
    _, again = _batch(logs, fleet, out)
    assert again["TRK-042"]["status"] == again["TRK-043"]["status"] == "skipped"
    fleet.write_text(HEADER + "TRK-042,truck,over-18t,5+,euro6,1\nTRK-043,truck,over-18t,5+,euro6,1\n")
    _, changed = _batch(logs, fleet, out)
    assert (changed["TRK-042"]["status"], changed["TRK-043"]["status"], changed["TRK-043"]["total"]) == ("skipped", "done", "2.60")


def test_the_invoices_do_not_depend_on_the_worker_count(logs, tmp_path):
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(HEADER + "TRK-042,truck,over-18t,5+,euro6,1\nTRK-043,truck,12-18t,3,euro5,2\nVAN-9,truck,7.5-12t,2,euro0-4,5\n")
    texts = []
    for workers in ("1", "2"):
        out = tmp_path / f"out{workers}"
        r, outcomes = _batch(logs, fleet, out, "--workers", workers)
        assert r.returncode == 0 and {o["status"] for o in outcomes.values()} == {"done"}, r.stderr
        texts.append([(out / "invoices" / v / f"{v}.json").read_bytes() for v in ("TRK-042", "TRK-043", "VAN-9")])
    assert texts[0] == texts[1]


@pytest.mark.parametrize("text, words", [
    ("vehicle,axles\nTRK-1,5+\n", ":1: no 'vehicle_class' column"),
    (HEADER + "TRK-1,truck,over-18t,5+,euro6,1\nTRK-1,truck,over-18t,4,euro6,1\n", ":3: vehicle 'TRK-1' is listed twice"),
    (HEADER + "TRK-1,truck,over-18t\n", ":2: 3 cells, the header has 6"),
    (HEADER + ",truck,over-18t,5+,euro6,1\n", ":2: a vehicle needs its id"),
    ("vehicle,vehicle_class,euro class\nTRK-1,truck,euro6\n", ":1: column 'euro class' is not a plain name"),
])  # fmt: skip
def test_a_bad_fleet_file_is_a_one_line_error_naming_its_line(tmp_path, text, words):
    path = tmp_path / "fleet.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=words.replace("(", r"\(").replace(")", r"\)")):
        read_fleet(str(path))


def test_the_cli_refuses_a_bad_fleet_before_writing_anything(logs, tmp_path):
    path = tmp_path / "fleet.csv"
    path.write_text("vehicle,axles\nTRK-1,5+\n")
    r, _ = _batch(logs, path, tmp_path / "out")
    err = r.stderr.decode()
    assert r.returncode == 1 and "no 'vehicle_class' column" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out").exists()
    r, _ = _batch(logs, path, tmp_path / "out2", "--vehicle-attr", "axles=4")
    assert r.returncode == 2 and b"leave out --vehicle-attr" in r.stderr


def test_empty_cells_are_attributes_a_vehicle_does_not_have(tmp_path):
    path = tmp_path / "fleet.csv"
    path.write_text("\ufeff" + HEADER + "BUS-7,bus,over-18t,3,euro6,\n\nTRK-9,truck,,,,\n")
    assert read_fleet(str(path)) == {"BUS-7": ("bus", {"axles": "3", "euro_class": "euro6", "weight_class": "over-18t"}),
                                     "TRK-9": ("truck", None)}  # fmt: skip
