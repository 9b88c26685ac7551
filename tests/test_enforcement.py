"""Enforcement: locate, tamper/evasion findings on constructed trips, and the roadside cross-check."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, SAMPLES, run_cli

from tollcli.geoobjects.build import build_geoobjects
from tollcli.geodesy import enu_shift2geodetic
from tollcli.simulate.drive import SimConfig, simulate
from tollcli.simulate.errors import FaultPlan
from tollcli.simulate.logs import nmea_lines
from tollcli.simulate.route import straight

START = (42.60, 2.88)
SPEED = 13.89


def _trip(seconds: float, drop=None, edit=None, **config) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A simulated rural drive north from START; ``drop`` (t0, t1) removes those seconds from the log."""
    traj = straight(*START, 0.0, SPEED, seconds)
    chunks = list(simulate(traj, SimConfig(env="rural", seed=4, **config)))
    epochs = pd.concat([c.epochs for c in chunks], ignore_index=True)
    sats = pd.concat([c.satellites for c in chunks], ignore_index=True)
    if drop:
        keep = ~((epochs["t_s"] >= drop[0]) & (epochs["t_s"] < drop[1]))
        sats = sats[sats["epoch"].isin(epochs.loc[keep, "epoch"])]
        epochs = epochs[keep]
    if edit:
        epochs = edit(epochs.copy())
    return epochs, sats


def _write(path, epochs, sats) -> str:
    path.write_text("\n".join(nmea_lines(epochs, sats)) + "\n")
    return str(path)


def _findings(log: str, *extra: str) -> list[dict]:
    result = run_cli("findings", log, "-q", "-o", "-", *extra)
    assert result.returncode == 0, result.stderr.decode()
    return json.loads(result.stdout)["findings"]


def _at(north_m: float, east_m: float = 0.0) -> list[float]:
    lat, lon = enu_shift2geodetic(START[0], START[1], east_m, north_m)
    return [round(float(lon), 8), round(float(lat), 8)]


@pytest.mark.parametrize("log", ["sim/rural-clean/drive.nmea", "sim/urban-clean/drive.nmea", "straight-drive.nmea"])
def test_a_clean_trip_has_no_finding(log):
    assert _findings(str(SAMPLES / log)) == []


def test_ten_minute_gap_across_a_tolled_segment(tmp_path):
    roads = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"id": "T-ON", "road_class": "motorway"},
         "geometry": {"type": "LineString", "coordinates": [_at(6000), _at(9000)]}},
        {"type": "Feature", "properties": {"id": "T-SIDE", "road_class": "motorway"},
         "geometry": {"type": "LineString", "coordinates": [_at(6000, 1500), _at(9000, 1500)]}},
        {"type": "Feature", "properties": {"id": "T-FAR", "road_class": "motorway"},
         "geometry": {"type": "LineString", "coordinates": [_at(6000, 30000), _at(9000, 30000)]}},
    ]}  # fmt: skip
    (tmp_path / "roads.geojson").write_text(json.dumps(roads))
    geo = tmp_path / "geo.geojson"
    geo.write_text(json.dumps(build_geoobjects(str(tmp_path / "roads.geojson"))))
    log = _write(tmp_path / "trip.nmea", *_trip(1200, drop=(300, 900)))
    found = _findings(log, "--geo", str(geo), "--vehicle-class", "truck")
    assert [f["kind"] for f in found] == ["gap"]
    gap = found[0]
    assert gap["category"] == "evasion"
    assert gap["evidence"]["duration_s"] == pytest.approx(601, abs=1)
    assert gap["evidence"]["distance_m"] == pytest.approx(601 * SPEED, rel=0.01)
    assert gap["evidence"]["geoobjects_on_line"] == ["T-ON"]
    assert gap["evidence"]["geoobjects_reachable"] == ["T-SIDE"]  # T-FAR is 30 km off: out of reach for a truck in 10 min
    assert gap["start_utc"].endswith("08:04:59.000Z") and gap["end_utc"].endswith("08:15:00.000Z")
    # the invoice carries the finding; the audit lists it
    inv = tmp_path / "invoice.json"
    result = run_cli("process", log, "--geo", str(geo), "--tariff", str(REPO / "geoobjects" / "example-tariff.toml"),
                     "--vehicle-class", "truck", "-q", "-o", str(inv))  # fmt: skip
    assert result.returncode == 0, result.stderr.decode()
    invoice = json.loads(inv.read_text())
    assert invoice["lines"] == [] and [f["kind"] for f in invoice["findings"]["items"]] == ["gap"]
    result = run_cli("audit", str(inv), "-q", "-o", str(tmp_path / "audit.json"))
    assert result.returncode == 0, result.stderr.decode()
    audit = json.loads((tmp_path / "audit.json").read_text())
    assert audit["findings"][0]["kind"] == "gap" and audit["findings"][0]["evidence"]["geoobjects_on_line"] == ["T-ON"]


def test_jammer_like_cn0_collapse(tmp_path):
    log = _write(tmp_path / "jam.nmea", *_trip(300, jam_at_s=[100.0], jam_duration_s=40.0, jam_db=12.0, track_min_dbhz=15.0))
    found = _findings(log)
    kinds = [f["kind"] for f in found]
    assert "cn0_collapse" in kinds
    hit = next(f for f in found if f["kind"] == "cn0_collapse")
    assert hit["category"] == "jamming"
    assert hit["start_utc"].endswith("08:01:40.000Z") and hit["end_utc"].endswith("08:02:19.000Z")  # the whole 40 s
    assert hit["evidence"]["baseline_cn0_dbhz"] - hit["evidence"]["cn0_dbhz"] == pytest.approx(12.0)
    # a jammer strong enough to lose every satellite: the count collapses and the fix is lost at speed
    log = _write(tmp_path / "jam2.nmea", *_trip(300, jam_at_s=[100.0], jam_duration_s=30.0, jam_db=25.0))
    kinds = {f["kind"] for f in _findings(log)}
    assert {"satellite_collapse", "fix_lost_at_speed"} <= kinds


def test_position_jump(tmp_path):
    def jump(epochs):
        row = epochs.index[epochs["t_s"] == 150.0][0]
        epochs.loc[row, "lat_deg"] += 0.01  # 1.1 km north for one epoch
        return epochs

    found = _findings(_write(tmp_path / "jump.nmea", *_trip(300, edit=jump)))
    jumps = [f for f in found if f["kind"] == "position_jump"]
    assert len(jumps) == 2  # there and back
    assert jumps[0]["start_utc"].endswith("08:02:29.000Z") and jumps[0]["evidence"]["implied_speed_mps"] > 1000
    assert all(f["category"] == "spoofing" for f in found)


def test_roadside_cloned_tag_missed_read_and_silent_trip(tmp_path):
    log = _write(tmp_path / "trip.nmea", *_trip(300))
    gantries = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"id": "G-ROUTE-1"}, "geometry": {"type": "Point", "coordinates": _at(120 * SPEED)}},
        {"type": "Feature", "properties": {"id": "G-ROUTE-2"}, "geometry": {"type": "Point", "coordinates": _at(240 * SPEED)}},
        {"type": "Feature", "properties": {"id": "G-FAR"}, "geometry": {"type": "Point", "coordinates": _at(0, 50_000)}},
    ]}  # fmt: skip
    (tmp_path / "gantries.geojson").write_text(json.dumps(gantries))
    (tmp_path / "reads.csv").write_text(
        "tag_id,gantry_id,time_utc\n"
        "TAG-1,G-ROUTE-1,2026-03-02T08:02:00Z\n"  # where the trip is: fine
        "TAG-1,G-FAR,2026-03-02T08:03:20Z\n"  # 50 km away at the same time: a cloned tag
        "TAG-1,G-ROUTE-1,2026-03-02T09:30:00Z\n"  # the trip's log is silent then
        "TAG-9,G-ROUTE-2,2026-03-02T08:04:00Z\n"  # another vehicle's tag
    )
    out = tmp_path / "enforce.json"
    result = run_cli("enforce", log, "--reads", str(tmp_path / "reads.csv"), "--gantries", str(tmp_path / "gantries.geojson"),
                     "--tag", "TAG-1", "-q", "-o", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr.decode()
    found = json.loads(out.read_text())["findings"]
    assert [f["kind"] for f in found] == ["read_far_from_trip", "missed_read", "read_without_trip"]
    far = found[0]
    assert far["gantry_id"] == "G-FAR" and far["distance_m"] == pytest.approx(50_000, rel=0.02)
    assert found[1]["gantry_id"] == "G-ROUTE-2" and found[1]["pass_utc"].startswith("2026-03-02T08:04:00")  # no read of TAG-1
    summary = run_cli("enforce", log, "--reads", str(tmp_path / "reads.csv"), "--gantries", str(tmp_path / "gantries.geojson"),
                      "--tag", "TAG-1", "-f", "csv", "-o", str(tmp_path / "enforce.csv"), "--json")  # fmt: skip
    assert json.loads(summary.stdout)["kinds"] == {"missed_read": 1, "read_far_from_trip": 1, "read_without_trip": 1}
    assert (tmp_path / "enforce.csv").read_text().splitlines()[0].startswith("kind,category,")


def test_roadside_bad_inputs_are_one_line_errors(tmp_path):
    log = str(SAMPLES / "straight-drive.nmea")
    (tmp_path / "g.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"id": "G1"}, "geometry": {"type": "Point", "coordinates": [2.9, 42.7]}}]}))
    (tmp_path / "bad.csv").write_text("tag,gantry,when\nA,G1,2024-05-06T08:00:00Z\n")
    (tmp_path / "unknown.csv").write_text("tag_id,gantry_id,time_utc\nA,G7,2024-05-06T08:00:00Z\n")
    (tmp_path / "badtime.csv").write_text("tag_id,gantry_id,time_utc\nA,G1,yesterday\n")
    for reads, message in (("bad.csv", "need columns tag_id, gantry_id, time_utc"), ("unknown.csv", "not in the gantry file: G7"),
                           ("badtime.csv", "line 2: time_utc 'yesterday' is not a time")):  # fmt: skip
        result = run_cli("enforce", log, "--reads", str(tmp_path / reads), "--gantries", str(tmp_path / "g.geojson"), "-o", "-")
        err = result.stderr.decode()
        assert result.returncode == 1 and message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_locate_last_trusted_and_later_untrusted(tmp_path):
    shutil.copy(SAMPLES / "sim" / "rural-clean" / "drive.nmea", tmp_path / "TRK-1.nmea")
    epochs, sats = _trip(160, faults=FaultPlan(bias_m=300.0, at_s=[120.0], duration_s=100.0))
    _write(tmp_path / "TRK-2.nmea", epochs, sats)
    out = tmp_path / "where.json"
    result = run_cli("locate", str(tmp_path / "TRK-1.nmea"), str(tmp_path / "TRK-2.nmea"), "-q", "-o", str(out))
    assert result.returncode == 0, result.stderr.decode()
    rows = json.loads(out.read_text())
    by = {(r["vehicle"], r["which"]): r for r in rows}
    truth = pd.read_csv(SAMPLES / "sim" / "rural-clean" / "truth.csv")
    last = by[("TRK-1", "last_trusted")]
    assert last["time_utc"] == truth["time_utc"].iloc[-1] and last["raim_status"] == "valid"
    assert abs(last["lat_deg"] - truth["lat_deg"].iloc[-1]) < 2e-4
    assert ("TRK-1", "last_any") not in by  # its last position is trusted
    t2 = by[("TRK-2", "last_trusted")]
    assert t2["time_utc"] < by[("TRK-2", "last_any")]["time_utc"]
    assert by[("TRK-2", "last_any")]["raim_status"] == "fault_detected"
    # the log's own header names the vehicle
    (tmp_path / "x.nmea").write_text("# vehicle: BUS-7\n" + (SAMPLES / "straight-drive.nmea").read_text())
    result = run_cli("locate", str(tmp_path / "x.nmea"), "-q", "-o", "-")
    assert result.stdout.decode().splitlines()[1].startswith("BUS-7,")
    # --at: where was TRK-1 at 08:01:00
    result = run_cli("locate", str(tmp_path / "TRK-1.nmea"), "--at", "2026-03-02T08:01:00", "-q", "-o", "-")
    table = pd.read_csv(pd.io.common.StringIO(result.stdout.decode()))
    assert table["time_utc"].tolist() == ["2026-03-02T08:01:00.000Z"]
    row = truth[truth["time_utc"] == "2026-03-02T08:01:00.000Z"].iloc[0]
    assert np.hypot((table["lat_deg"].iloc[0] - row["lat_deg"]) * 111_000, (table["lon_deg"].iloc[0] - row["lon_deg"]) * 82_000) < 30


#: the judged findings on gpsd's logs (docs/enforcement.md): a change of rules or thresholds shows here
GPSD_FINDINGS = {
    "ac12.log": ["time_jump"] * 6, "ac12_binary.log": ["time_jump"] * 5, "bt451.log": ["time_jump"],
    "bu353-glonass.log": ["satellite_collapse"], "ericsson-gru04.log": ["time_jump"],
    "garmin-10x.log": ["cn0_collapse", "satellite_collapse"], "gp-320fw-2019-04-07-coldboot.log": ["time_jump", "time_jump"],  # cold boot: the clock jumps, then to 1999 (no-fix dates are not read)
    "iTrek.log": ["time_jump"],  # two recordings concatenated
    "humminbird-M37.log": ["time_jump"], "nl2008u.log": ["gap"],
    "sl869.log": ["position_jump"], "ublox-lea-4h.log": ["gap"], "unicore-um621.log": ["cn0_collapse", "satellite_collapse"],
}  # fmt: skip


def test_findings_on_every_gpsd_log_are_the_judged_ones():
    from conftest import shared

    from tollcli.enforcement.findings import trip_findings
    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import iter_integrity
    from tollcli.readers.nmea import ReadStats

    folder = shared("gpsd")
    logs = sorted(folder.glob("*.log"))
    assert len(logs) == 177
    got = {}
    for log in logs:
        chunks = list(iter_integrity(str(log), "nmea", RaimParams(), stats=ReadStats()))
        if not chunks:
            continue
        table = pd.concat([c.table for c in chunks], ignore_index=True)
        sats = pd.concat([c.satellites for c in chunks], ignore_index=True)
        kinds = sorted(f["kind"] for f in trip_findings(table, sats, table))
        if kinds:
            got[log.name] = kinds
    assert got == GPSD_FINDINGS


def _shift_times(epochs):
    late = epochs["t_s"] >= 150.0
    epochs.loc[late, "time_utc"] = epochs.loc[late, "time_utc"] - pd.Timedelta(seconds=40)
    return epochs


def _speed(value_mps, t0, t1):
    def edit(epochs):
        epochs.loc[(epochs["t_s"] >= t0) & (epochs["t_s"] < t1), "speed_mps"] = value_mps
        return epochs

    return edit


def _rewrite(path, t0: str, t1: str, change) -> None:
    """Apply ``change(line)`` to the NMEA lines whose time field lies in [t0, t1] (hhmmss strings)."""
    lines = []
    for line in path.read_text().splitlines():
        fields = line.split(",")
        if line.startswith("$GNRMC") and t0 <= fields[1][:6] <= t1:
            lines.extend(change(line))
        else:
            lines.append(line)
    path.write_text("\n".join(lines) + "\n")


def _rmc_elsewhere(line):
    from tollcli.readers.nmea.compose import with_checksum

    fields = line[1 : line.index("*")].split(",")
    fields[3] = f"{float(fields[3]) + 0.06:.7f}"  # 0.06 arc-minutes north: 111 m
    return [with_checksum(",".join(fields))]


def _zda_next_day(line):
    from tollcli.readers.nmea.compose import with_checksum

    fields = line[1 : line.index("*")].split(",")
    return [line, with_checksum(f"GNZDA,{fields[1]},03,03,2026,00,00")]  # RMC says 02 March


@pytest.mark.parametrize(
    ("kind", "trip", "rewrite"),
    [
        ("overspeed", dict(edit=_speed(90.0, 100, 106)), None),
        ("doppler_mismatch", dict(edit=_speed(7.0, 100, 140)), None),
        ("time_jump", dict(edit=_shift_times), None),
        ("cn0_uniform", dict(cn0_dbhz=48.0), None),
        ("raim_persistent_alarm", dict(faults=FaultPlan(bias_m=150.0, at_s=[100.0], duration_s=60.0)), None),
        ("position_disagreement", {}, ("080140", "080144", _rmc_elsewhere)),
        ("date_disagreement", {}, ("080200", "080202", _zda_next_day)),
    ],
)
def test_each_spoofing_sign_on_a_constructed_trip(tmp_path, kind, trip, rewrite):
    log = tmp_path / "trip.nmea"
    _write(log, *_trip(300, **trip))
    if rewrite:
        _rewrite(log, *rewrite)
    found = [f for f in _findings(str(log)) if f["kind"] == kind]
    assert found, f"no {kind}"
    assert all(f["category"] == "spoofing" for f in found)
    if kind == "position_disagreement":
        assert found[0]["evidence"]["max_disagreement_m"] == pytest.approx(111, abs=2)
        assert found[0]["start_utc"].endswith("08:01:40.000Z") and found[0]["end_utc"].endswith("08:01:44.000Z")
    if kind == "date_disagreement":
        assert found[0]["evidence"]["zda_minus_rmc_days"] == 1
    if kind == "time_jump":
        assert found[0]["evidence"]["step_s"] == pytest.approx(-39.0)
    if kind == "overspeed":
        assert found[0]["evidence"]["max_reported_mps"] == pytest.approx(90.0, abs=0.01)


def test_locate_tells_apart_logs_of_one_name_recorded_at_the_same_time(tmp_path):
    """samples/sim/*/drive.nmea: four drives of the same morning are four vehicles; one name on two days is one vehicle."""
    import json as _json

    from conftest import SAMPLES, run_cli

    sims = sorted(str(p) for p in (SAMPLES / "sim").glob("*/drive.nmea"))
    rows = _json.loads(run_cli("locate", *sims, "-q", "--json").stdout)
    assert len({r["vehicle"] for r in rows}) == 4 and {r["vehicle"] for r in rows} >= {"urban-fault/drive"}
    for day, src in (("day1", SAMPLES / "straight-drive.nmea"), ("day2", SAMPLES / "sim" / "rural-clean" / "drive.nmea")):
        (tmp_path / day).mkdir()
        (tmp_path / day / "TRK-042.nmea").write_bytes(src.read_bytes())
    rows = _json.loads(run_cli("locate", str(tmp_path / "day1" / "TRK-042.nmea"), str(tmp_path / "day2" / "TRK-042.nmea"),
                               "-q", "--json").stdout)  # fmt: skip
    assert {r["vehicle"] for r in rows} == {"TRK-042"} and all("day2" in r["log"] for r in rows)


def test_locate_at_takes_the_time_format_the_outputs_write():
    from conftest import SAMPLES, run_cli

    log = str(SAMPLES / "sim" / "rural-clean" / "drive.nmea")
    for at in ("2026-03-02T08:01:00.000Z", "2026-03-02T08:01:00Z", "2026-03-02T08:01:00"):
        result = run_cli("locate", log, "--at", at, "-q")
        assert result.returncode == 0 and "2026-03-02T08:01:00.000Z" in result.stdout.decode(), at


def test_binomial_tail_is_scipys():
    """The numpy binomial tail the persistent-alarm finding uses equals scipy's survival function."""
    from scipy.stats import binom

    from tollcli.stats import binomial_tail

    rng = np.random.default_rng(7)
    n = rng.integers(1, 80, 2000)
    k = rng.integers(0, 82, 2000)
    p = rng.random(2000)
    p[:50], p[50:100] = 1.0, 1e-12
    assert np.allclose(binomial_tail(k, n, p), binom.sf(k - 1, n, p), rtol=1e-9, atol=1e-15)
    assert binomial_tail(np.array([24]), np.array([30]), np.array([0.5]))[0] == pytest.approx(0.000715, rel=1e-2)


@pytest.mark.parametrize("seed", range(8))
def test_cn0_summary_orders_the_values_as_lexsort_does(seed):
    """The C/N0 summary's sort (one exact key where every C/N0 is a whole dB-Hz below 256) gives the values and rows of
    ``np.lexsort((cn0, row))`` to the bit, and so the summary of a lexsort: whole values, fractional ones (Android's),
    rows in order or not, values up to the edges (255, and 256 which takes the general path)."""
    from tollcli.enforcement.trip import _sorted_by_epoch, cn0_summary

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4000))
    row = rng.integers(0, int(rng.integers(1, 500)), n)
    if seed % 2:
        row = np.sort(row)
    cn0 = rng.integers(1, 257, n).astype(float) if seed < 6 else rng.uniform(0.1, 60.0, n)
    if seed == 4:
        cn0 = np.minimum(cn0, 255.0)
    order = np.lexsort((cn0, row))
    x, r = _sorted_by_epoch(cn0, row)
    np.testing.assert_array_equal(x, cn0[order])
    np.testing.assert_array_equal(r, row[order])
    summary = cn0_summary(pd.DataFrame({"epoch": row + 7, "cn0_dbhz": cn0}), int(row.max()) + 1, 7)
    for k in np.flatnonzero(np.bincount(row)):
        values = np.sort(cn0[row == k])
        assert summary["n_tracked"].iat[k] == values.size
        assert summary["cn0_median"].iat[k] == np.median(values)
        assert summary["cn0_p80"].iat[k] == pytest.approx(np.percentile(values, 80), rel=1e-12)
