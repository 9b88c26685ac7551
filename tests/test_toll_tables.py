"""Per-km toll tables: rates by vehicle attributes, validity dates, known-answer invoices, typos refused."""

from __future__ import annotations

import datetime as dt
import itertools
import json
import random
from decimal import ROUND_HALF_EVEN, ROUND_HALF_UP, Decimal
from pathlib import Path

import pytest
from conftest import REPO, run_cli

from tollcli.charging.tariffs import load_tariff
from tollcli.errors import DataError

TRUCK = REPO / "geoobjects" / "example-truck-tariff.toml"
GEO = REPO / "geoobjects" / "example-geoobjects.geojson"
ROADS = REPO / "geoobjects" / "example-roads.geojson"
UTC = dt.timezone.utc
HEAVY = {"vehicle_class": "truck", "weight_class": "over-18t", "axles": "5+", "euro_class": "euro6", "co2_class": "1"}
#: the last second of the first half-year in Paris (UTC+2 in summer) and the first of the second
LAST_H1 = dt.datetime(2024, 6, 30, 21, 59, 59, tzinfo=UTC)
FIRST_H2 = dt.datetime(2024, 6, 30, 22, 0, 0, tzinfo=UTC)


def _tariff(tmp_path, text: str):
    path = tmp_path / "t.toml"
    path.write_text(text)
    return load_tariff(str(path))


HEAD = 'currency = "EUR"\ntimezone = "Europe/Berlin"\n\n[vehicle]\neuro_class = ["euro5", "euro6"]\naxles = [2, 3, 4, "5+"]\n\n'


# ---------------------------------------------------------------- known answers
def test_known_answers_of_the_example_truck_tariff():
    t = load_tariff(str(TRUCK))
    # H1, 40 t, 5+ axles, Euro 6, CO2 class 1: 0.198 + 0.011 + 0.002 + 0.133 = 0.344 €/km
    p = t.price("A9-N2", "motorway", 1651.0, HEAVY, LAST_H1)
    assert (p.table, p.per_km, p.per_passage, p.length_km) == ("2024-H1", Decimal("0.344"), Decimal(0), Decimal("1.651"))
    assert p.fee == Decimal("0.57")  # 0.344 × 1.651 = 0.567944
    assert set(p.components) == {"infrastructure", "air", "noise", "co2"}
    # H2 from local midnight: 0.212 + 0.011 + 0.002 + 0.133 = 0.358 €/km, and the bridge's 1.50 per passage
    p = t.price("A9-N2", "motorway", 1651.0, HEAVY, FIRST_H2)
    assert (p.table, p.per_km, p.per_passage) == ("2024-H2", Decimal("0.358"), Decimal("1.50"))
    assert p.fee == Decimal("2.09")  # 1.50 + 0.358 × 1.651 = 2.091058
    # [length_km] wins over the geo-object's own length: A9-N1 is 1.471 km whatever the geometry says
    assert t.price("A9-N1", "motorway", 9999.0, HEAVY, LAST_H1).length_km == Decimal("1.471")
    # a 12 t Euro 5 truck, CO2 class 3, 2 axles: 0.093 + 0.011 + 0.002 + 0.088 = 0.194 €/km over 10 km
    light = {"vehicle_class": "truck", "weight_class": "7.5-12t", "axles": "2", "euro_class": "euro5", "co2_class": "3"}
    assert t.price("x", "expressway", 10_000.0, light, LAST_H1).fee == Decimal("1.94")
    # an old Euro 4 truck pays the higher air part: 0.344 − 0.011 + 0.021 = 0.354 €/km
    old = {**HEAVY, "euro_class": "euro0-4"}
    assert t.price("x", "motorway", 10_000.0, old, LAST_H1).per_km == Decimal("0.354")


def test_rounding_is_half_up_once_per_line_and_lengths_are_whole_metres(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_km = 0.213\n')
    when = dt.datetime(2024, 3, 1, tzinfo=UTC)
    vehicle = {"vehicle_class": "truck"}
    exact = Decimal("0.213") * Decimal(5)
    assert exact == Decimal("1.065") and exact.quantize(Decimal("0.01"), ROUND_HALF_EVEN) == Decimal("1.06")
    assert t.price("g", "m", 5000.0, vehicle, when).fee == Decimal("1.07")  # half-up, not the banker's 1.06
    # the section length is counted in whole metres, half-up: 4999.5 m → 5.000 km, 4999.49 m → 4.999 km
    assert t.price("g", "m", 4999.5, vehicle, when).length_km == Decimal("5.000")
    assert t.price("g", "m", 4999.49, vehicle, when).length_km == Decimal("4.999")
    # no length at all: an error naming the geo-object, never a fee of 0
    with pytest.raises(DataError, match="'g' has no length"):
        t.price("g", "m", float("nan"), vehicle, when)


def test_a_band_scales_the_per_km_fee_with_one_rounding(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[band]]\nname = "night"\nstart = "22:00"\nend = "06:00"\nfactor = 0.5\n\n'
                                 '[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_km = 0.213\n')  # fmt: skip
    night = dt.datetime(2024, 3, 1, 23, 30, tzinfo=UTC)  # 00:30 in Berlin
    p = t.price("g", "m", 5000.0, {"vehicle_class": "truck"}, night)
    assert (p.band, p.fee) == ("night", Decimal("0.53"))  # 1.065 × 0.5 = 0.5325 → 0.53 (not 1.07 × 0.5 = 0.535 → 0.54)


def test_the_table_in_force_is_chosen_by_the_local_date_of_entry():
    t = load_tariff(str(TRUCK))
    for when, table in ((LAST_H1, "2024-H1"), (FIRST_H2, "2024-H2"),
                        (dt.datetime(2023, 12, 31, 23, 0, tzinfo=UTC), "2024-H1"),  # midnight in Paris (UTC+1)
                        (dt.datetime(2030, 1, 1, tzinfo=UTC), "2024-H2")):  # fmt: skip
        assert t.price("x", "motorway", 1000.0, HEAVY, when).table == table
    with pytest.raises(DataError, match="no tariff table in force at 2023-12-31T22:59:59Z"):
        t.price("x", "motorway", 1000.0, HEAVY, dt.datetime(2023, 12, 31, 22, 59, 59, tzinfo=UTC))


def test_valid_until_ends_a_table_and_leaves_a_gap(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[table]]\nvalid_from = 2024-01-01\nvalid_until = 2024-02-01\n[[table.rate]]\nper_passage = 1\n'
                                 '[[table]]\nvalid_from = 2024-03-01\n[[table.rate]]\nper_passage = 2\n')  # fmt: skip
    v = {"vehicle_class": "car"}
    assert t.price("g", "m", None, v, dt.datetime(2024, 1, 31, 22, 59, tzinfo=UTC)).fee == Decimal("1.00")
    with pytest.raises(DataError, match="no tariff table in force"):
        t.price("g", "m", None, v, dt.datetime(2024, 2, 10, tzinfo=UTC))
    assert t.price("g", "m", None, v, dt.datetime(2024, 3, 10, tzinfo=UTC)).fee == Decimal("2.00")


def test_the_most_specific_row_of_a_component_applies(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[table]]\nvalid_from = 2024-01-01\n'
                '[[table.rate]]\nper_km = 0.1\n'
                '[[table.rate]]\nroad_class = ["motorway", "trunk"]\nper_km = 0.2\n'
                '[[table.rate]]\ngeoobject = "bridge"\nper_km = 0.3\n'
                '[[table.rate]]\ncomponent = "surcharge"\neuro_class = "euro5"\nper_passage = 0.05\n')  # fmt: skip
    when, v6, v5 = dt.datetime(2024, 5, 1, tzinfo=UTC), {"vehicle_class": "truck", "euro_class": "euro6"}, {"vehicle_class": "truck", "euro_class": "euro5"}
    assert t.price("a", "primary", 10_000.0, v6, when).fee == Decimal("1.00")
    assert t.price("a", "trunk", 10_000.0, v6, when).fee == Decimal("2.00")
    assert t.price("bridge", "trunk", 10_000.0, v6, when).fee == Decimal("3.00")
    assert t.price("bridge", "trunk", 10_000.0, v5, when).fee == Decimal("3.05")


# ---------------------------------------------------------------- the file is refused, with its line, on any doubt
@pytest.mark.parametrize("body, line, words", [
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_kn = 0.1\n', 11, "unknown key 'per_kn'"),
    ('[[table]]\nvalid_form = 2024-01-01\n[[table.rate]]\nper_km = 0.1\n', 9, "unknown key 'valid_form'"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\neuro_clas = "euro6"\nper_km = 0.1\n', 11, "unknown key 'euro_clas'"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\neuro_class = "euro7"\nper_km = 0.1\n', 11, "euro_class 'euro7' is not one of"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\naxles = 6\nper_km = 0.1\n', 11, "axles '6' is not one of"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_km = -0.1\n', 11, "≥ 0"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\ncomponent = "a"\n', 10, "no amount"),
    ('[[table]]\nvalid_from = "soon"\n[[table.rate]]\nper_km = 0.1\n', 9, "TOML date"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_km = 0.1\n[[table.rate]]\naxles = 4\nper_km = 0.2\n', 12,
     "both apply"),
    ('[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\naxles = [2, 3]\nper_km = 0.1\n'
     '[[table.rate]]\naxles = [3, 4]\nper_km = 0.2\n', 13, "both apply"),
    ('[[table]]\nvalid_from = 2024-01-01\nvalid_until = 2023-01-01\n[[table.rate]]\nper_km = 0.1\n', 10, "not after"),
    ('[road_class.motorway]\ncar = 1\n[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\nper_km = 0.1\n', 8, "not both"),
    ('[lengths_km]\n"A9-N1" = 1.2\n', 8, "unknown key 'lengths_km'"),
])  # fmt: skip
def test_a_doubtful_table_is_a_one_line_error_naming_its_line(tmp_path, body, line, words):
    with pytest.raises(DataError) as err:
        _tariff(tmp_path, HEAD + body)
    message = str(err.value)
    assert f"t.toml:{line}:" in message and words in message and "\n" not in message, message


def test_rows_that_cannot_meet_are_not_ambiguous(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[table]]\nvalid_from = 2024-01-01\n'
                '[[table.rate]]\naxles = [2, 3]\nper_km = 0.1\n[[table.rate]]\naxles = [4, "5+"]\nper_km = 0.2\n'
                '[[table.rate]]\nroad_class = "a"\naxles = 2\nper_km = 0.3\n[[table.rate]]\nroad_class = "b"\naxles = 2\nper_km = 0.4\n')  # fmt: skip
    assert len(t.tables[0].rates) == 4


def test_a_vehicle_without_an_attribute_a_rate_needs_is_an_error(tmp_path):
    t = _tariff(tmp_path, HEAD + '[[table]]\nvalid_from = 2024-01-01\n[[table.rate]]\neuro_class = "euro6"\nper_km = 0.1\n'
                                 '[[table.rate]]\neuro_class = "euro5"\nper_km = 0.2\n')  # fmt: skip
    with pytest.raises(DataError, match=r"t.toml:10: this rate depends on the vehicle's euro_class"):
        t.price("g", "m", 1000.0, {"vehicle_class": "truck"}, dt.datetime(2024, 5, 1, tzinfo=UTC))


# ---------------------------------------------------------------- properties
def _every_vehicle(t):
    names = sorted(t.vehicle)
    for values in itertools.product(*(sorted(t.vehicle[n]) for n in names)):
        yield dict(zip(names, values))


def test_every_declared_vehicle_has_a_price_on_every_geo_object_of_the_example():
    """The example table is complete: each of the 2·3·4·4·5 = 480 vehicles is priced on both sample geo-objects in
    both tables, and the fee is the sum of its parts, rounded once half-up."""
    t = load_tariff(str(TRUCK))
    n = 0
    for vehicle in _every_vehicle(t):
        for when in (LAST_H1, FIRST_H2):
            for gid, length_m in (("A9-N1", 1470.8), ("A9-N2", 1651.0)):
                p = t.price(gid, "motorway", length_m, vehicle, when)
                parts = sum(Decimal(c["per_km"]) for c in p.components.values())
                fixed = sum(Decimal(c["per_passage"]) for c in p.components.values())
                assert p.per_km == parts and p.fee == (fixed + parts * p.length_km).quantize(Decimal("0.01"), ROUND_HALF_UP)
                n += 1
    assert n == 480 * 4


def test_reordered_rows_and_tables_give_the_same_prices(tmp_path):
    """Rows shuffled inside each table and the tables swapped: the same price for every vehicle, geo-object and date."""
    text = TRUCK.read_text()
    head, *tables = text.split("\n[[table]]\n")
    shuffled = []
    rng = random.Random(7)
    for block in tables:
        block, _, lengths = block.partition("\n[length_km]")
        top, *rows = block.split("\n[[table.rate]]\n")
        rng.shuffle(rows)
        shuffled.append("\n[[table.rate]]\n".join([top, *rows]) + ("\n[length_km]" + lengths if lengths else ""))
    other = head + "".join("\n[[table]]\n" + b for b in (shuffled[1], shuffled[0]))
    a, b = load_tariff(str(TRUCK)), _tariff(tmp_path, other)
    assert other != text and b.length_km == a.length_km
    for vehicle in _every_vehicle(a):
        for when in (LAST_H1, FIRST_H2):
            pa, pb = (t.price("A9-N2", "motorway", 1651.0, vehicle, when) for t in (a, b))
            assert (pa.fee, pa.band, pa.table, pa.length_km, pa.per_km, pa.per_passage) == \
                   (pb.fee, pb.band, pb.table, pb.length_km, pb.per_km, pb.per_passage)
            assert {c: (v["per_km"], v["per_passage"]) for c, v in pa.components.items()} == \
                   {c: (v["per_km"], v["per_passage"]) for c, v in pb.components.items()}


# ---------------------------------------------------------------- end to end
ATTRS = ("--vehicle-class", "truck", "--vehicle-attr", "weight_class=over-18t", "--vehicle-attr", "axles=5+",
         "--vehicle-attr", "euro_class=euro6", "--vehicle-attr", "co2_class=1")  # fmt: skip


@pytest.fixture(scope="module")
def midnight_drive(tmp_path_factory):
    """The sample motorway driven from 23:58:30 Paris time on 30 June 2024: A9-N1 entered under the first
    half-year's table, A9-N2 (entered after local midnight) under the second's."""
    out = tmp_path_factory.mktemp("midnight") / "drive"
    r = run_cli("simulate", "--route", str(ROADS), "--via", "A9-N1,A9-N2", "--geo", str(GEO), "--env", "rural", "--seed", "1",
                "--start-utc", "2024-06-30T21:58:30", "-o", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    return out


def test_a_drive_across_the_validity_date_is_charged_by_the_right_tables(midnight_drive, tmp_path):
    inv = tmp_path / "invoice.json"
    r = run_cli("process", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), *ATTRS, "-o", str(inv))
    assert r.returncode == 0, r.stderr
    doc = json.loads(inv.read_text())
    geo = {f["properties"]["id"]: f["properties"] for f in json.loads(GEO.read_text())["features"]}
    lines = {line["geoobject"]: line for line in doc["lines"]}
    assert set(lines) == set(json.loads((midnight_drive / "truth-geoobjects.json").read_text())) == {"A9-N1", "A9-N2"}
    n1, n2 = lines["A9-N1"], lines["A9-N2"]
    assert n1["entry_utc"] < "2024-06-30T22:00:00" <= n2["entry_utc"]
    assert (n1["tariff_table"], n1["length_km"], n1["rate_per_km"], n1["fee"]) == ("2024-H1", "1.471", "0.344", "0.51")
    section_km = str(Decimal(round(geo["A9-N2"]["section_length_m"])).scaleb(-3))
    assert (n2["tariff_table"], n2["length_km"], n2["rate_per_km"], n2["rate_per_passage"]) == ("2024-H2", section_km, "0.358", "1.50")
    assert Decimal(n2["fee"]) == (Decimal("1.50") + Decimal("0.358") * Decimal(section_km)).quantize(Decimal("0.01"), ROUND_HALF_UP)
    assert doc["total"] == str(Decimal(n1["fee"]) + Decimal(n2["fee"]))
    assert doc["vehicle_attributes"] == {"axles": "5+", "co2_class": "1", "euro_class": "euro6", "weight_class": "over-18t"}
    assert run_cli("verify", str(inv)).returncode == 0  # the attributes are recorded: verify reproduces it
    csv = tmp_path / "invoice.csv"
    assert run_cli("process", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), *ATTRS,
                   "-o", str(csv), "-q").returncode == 0  # fmt: skip
    header, first, *_ = csv.read_text().splitlines()
    assert header.split(",")[8:13] == ["band", "tariff_table", "length_km", "rate_per_km", "rate_per_passage"]
    assert first.split(",")[9:11] == ["2024-H1", "1.471"]
    page = tmp_path / "report.html"
    assert run_cli("report", str(inv), "-o", str(page)).returncode == 0
    assert "<th>rate per km</th>" in page.read_text() and "<td>2024-H1</td><td>1.471</td><td>0.344</td><td>0.51</td>" in page.read_text()


def test_the_same_drive_a_day_earlier_is_all_first_table(midnight_drive, tmp_path):
    """Metamorphic: the drive shifted back 24 h only changes which table the second passage uses."""
    shifted = tmp_path / "drive"
    r = run_cli("simulate", "--route", str(ROADS), "--via", "A9-N1,A9-N2", "--geo", str(GEO), "--env", "rural", "--seed", "1",
                "--start-utc", "2024-06-29T21:58:30", "-o", str(shifted))  # fmt: skip
    assert r.returncode == 0, r.stderr
    inv = tmp_path / "invoice.json"
    assert run_cli("process", str(shifted / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), *ATTRS, "-o", str(inv)).returncode == 0
    lines = {line["geoobject"]: line for line in json.loads(inv.read_text())["lines"]}
    assert {g: line["tariff_table"] for g, line in lines.items()} == {"A9-N1": "2024-H1", "A9-N2": "2024-H1"}
    assert lines["A9-N2"]["rate_per_passage"] == "0" and lines["A9-N2"]["fee"] == "0.57"  # 0.344 × 1.651, no bridge part yet


@pytest.mark.parametrize("extra, words", [
    (("--vehicle-attr", "euro_class=euro7"), "euro_class 'euro7' is not one of"),
    (("--vehicle-attr", "eurocls=euro6"), "'eurocls' is not a vehicle attribute"),
    (("--vehicle-attr", "euro_class"), "KEY=VALUE"),
    (("--vehicle-attr", "euro_class=euro6", "--vehicle-attr", "euro_class=euro5"), "given twice"),
    (("--vehicle-attr", "euro_class=euro6", "--vehicle-class", "van"), "not a vehicle class of the tariff"),
])  # fmt: skip
def test_a_vehicle_the_tariff_does_not_know_is_a_one_line_usage_error(midnight_drive, tmp_path, extra, words):
    without_euro = [a for a in ATTRS if not a.startswith("euro_class")]
    without_euro = [a for i, a in enumerate(without_euro) if not (a == "--vehicle-attr" and without_euro[i + 1] == "--vehicle-attr")]
    assert without_euro.count("--vehicle-attr") == 3
    r = run_cli("process", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), *without_euro, *extra,
                "-o", str(tmp_path / "i.json"))  # fmt: skip
    err = r.stderr.decode()
    assert r.returncode == 2 and words in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "i.json").exists()


def test_a_vehicle_lacking_an_attribute_the_table_needs_fails_naming_it(midnight_drive, tmp_path):
    r = run_cli("process", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), "--vehicle-class", "truck",
                "--vehicle-attr", "weight_class=over-18t", "-o", str(tmp_path / "i.json"))  # fmt: skip
    err = r.stderr.decode()
    assert r.returncode != 0 and "depends on the vehicle's" in err and "Traceback" not in err, err
    assert not (tmp_path / "i.json").exists()


def test_the_tariff_documentation_example_is_the_bundled_file():
    """docs/tariffs.md shows the complete example: it is the bundled example-truck-tariff.toml, which loads."""
    doc = (Path(REPO) / "docs" / "tariffs.md").read_text()
    assert TRUCK.read_text().strip() in doc
    load_tariff(str(TRUCK))


@pytest.mark.parametrize("row, words", [
    ('[[table.rate]]\nroad_class = "motorwya"\nper_km = 0.1\n', "t.toml:10: the rate names road class 'motorwya'"),
    ('[[table.rate]]\ngeoobject = "A9-N3"\nper_passage = 1\n', "t.toml:10: the rate names geo-object 'A9-N3'"),
    ('[[table.rate]]\nper_km = 0.1\n[length_km]\n"A9-M1" = 1.5\n', "[length_km] names geo-object 'A9-M1'"),
])  # fmt: skip
def test_a_tariff_naming_what_the_network_lacks_is_refused(midnight_drive, tmp_path, row, words):
    """A misspelt geo-object id or road class would leave its row unused (a fee changed silently): refused, one line."""
    tariff = tmp_path / "t.toml"
    tariff.write_text(HEAD + "[[table]]\nvalid_from = 2024-01-01\n" + row)
    r = run_cli("process", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(tariff), "--vehicle-class", "truck",
                "-o", str(tmp_path / "i.json"))  # fmt: skip
    err = r.stderr.decode()
    assert r.returncode == 1 and words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "i.json").exists()


def test_batch_records_the_vehicle_and_redoes_a_log_when_it_changes(midnight_drive, tmp_path):
    """The vehicle's attributes decide the invoice: the same attributes find it up to date, other ones redo it."""
    def run(*attrs):
        r = run_cli("batch", str(midnight_drive / "drive.nmea"), "--geo", str(GEO), "--tariff", str(TRUCK), "--vehicle-class", "truck",
                    *attrs, "-o", str(tmp_path / "out"), "--workers", "1", "-q", "--json")  # fmt: skip
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    heavy = ATTRS[2:]
    assert (run(*heavy)["done"], run(*heavy)["skipped"]) == (1, 1)
    four_axles = [a.replace("axles=5+", "axles=4") for a in heavy]
    again = run(*four_axles)
    assert again["done"] == 1 and again["totals"] == {"EUR": "2.52"}  # 0.320 × 1.471 → 0.47 (H1), 1.50 + 0.332 × 1.651 → 2.05 (H2)
