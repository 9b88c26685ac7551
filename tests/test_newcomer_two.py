"""A newcomer's day, round two (issue 51): each numbered point of what went wrong, on real logs where there are some.

1. no money from an invented clock; 2. a passage's positions counted in one vocabulary; 3. a GST that contradicts itself
is no evidence; 4. what gpsd's JSON lost; 5. a log far from every geo-object says so; 6. no geo-object too short to be
recognised; 7. the environment the map declares; 8. availability in the audit; 9. info says where a log is; 10. exit
codes and batch's checks once; 11. tariff class keys; 12. small ones.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from conftest import BERLIN_START, REPO, SAMPLES, roads_along_the_berlin_drive, run_cli, shared

from tollcli.readers.nmea.fields import checksum

TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
BERLIN = ("smartloc", "Berlin_Potsdamer_Platz_Input.txt")
BERLIN_TRUTH = ("smartloc", "Berlin_Potsdamer_Platz_GT.txt")


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


def _process(log, geo, *extra, tariff=TARIFF, out: Path) -> tuple[int, str, dict | None]:
    proc = run_cli("process", str(log), "--geo", str(geo), "--tariff", str(tariff), "-o", str(out), "-q", *extra)
    invoice = json.loads(out.read_text()) if proc.returncode == 0 else None
    return proc.returncode, proc.stderr.decode(), invoice


# ------------------------------------------------------------------------------------------------ 1. time
def test_a_log_of_seconds_from_its_start_is_not_priced_on_an_invented_clock(tmp_path):
    """The Berlin drive (libRSF: seconds from the start, no date) was dated 1970-01-01 and priced in the night band
    (0.76 instead of 0.95); ``--date`` was ignored. Now: no invoice without ``--start-time`` (``--date`` alone is said to
    give no time of day), and with it the period, the bands and the audit's truth are on that clock."""
    log, geo = shared(*BERLIN), roads_along_the_berlin_drive(tmp_path)
    code, err, _ = _process(log, geo, out=tmp_path / "a.json")
    assert code == 1 and "--start-time" in err and "seconds from the start" in err and err.count("\n") == 1
    code, err, _ = _process(log, geo, "--date", "2019-06-04", out=tmp_path / "b.json")
    assert code == 1 and "--date 2019-06-04 gives no time of day" in err
    code, err, _ = _process(log, geo, "--start-time", "2019-06-04T12:00:00", out=tmp_path / "c.json")
    assert code == 2 and "UTC offset" in err  # a time without its offset is no instant
    code, err, _ = _process(log, geo, "--start-time", BERLIN_START, "--date", "2019-06-05", out=tmp_path / "d.json")
    assert code == 2 and "contradicts --start-time" in err
    code, err, noon = _process(log, geo, "--start-time", BERLIN_START, out=tmp_path / "noon.json")
    assert code == 0, err
    assert noon["period"]["start_utc"] == "2019-06-04T10:00:00.000Z" and noon["parameters"]["start_time"] == "2019-06-04T10:00:00.000Z"
    assert noon["lines"] and {line["band"] for line in noon["lines"]} == {""} and {line["fee"] for line in noon["lines"]} == {"0.95"}
    code, err, night = _process(log, geo, "--start-time", "2019-06-04T23:00:00+02:00", out=tmp_path / "night.json")
    assert code == 0 and {line["band"] for line in night["lines"]} == {"night"}
    # metamorphic: the clock moves the money, never what was charged
    assert [line["geoobject"] for line in night["lines"]] == [line["geoobject"] for line in noon["lines"]]
    # the audit places the truth (also seconds from its start) where the invoice placed the log
    report = tmp_path / "audit.json"
    proc = run_cli("audit", str(tmp_path / "noon.json"), "--truth", str(shared(*BERLIN_TRUTH)), "--geo", str(geo), "--tariff", TARIFF,
                   "-q", "-o", str(report))  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    audit = json.loads(report.read_text())
    assert audit["false_recognitions"] == 0 and audit["passages_driven"] > len(noon["lines"])
    assert all(p["entry_utc"].startswith("2019-06-04T1") for p in audit["truth_passages"])


def test_a_date_that_contradicts_the_logs_own_is_an_error_naming_both(tmp_path):
    """``--date`` is for logs without RMC/ZDA; given for a log that has them and disagreeing, it was silently half used."""
    code, err, _ = _process(SAMPLES / "straight-drive.nmea", GEO, "--date", "2019-06-01", out=tmp_path / "x.json")
    assert code == 1 and "straight-drive.nmea:3:" in err and "2019-06-01" in err and "2024-05-06" in err
    code, err, invoice = _process(SAMPLES / "straight-drive.nmea", GEO, "--date", "2024-05-06", out=tmp_path / "y.json")
    assert code == 0 and invoice["total"] == "1.90"  # agreeing: as without it


# ------------------------------------------------------------------------------------------------ 2. one vocabulary
def test_a_passages_statuses_add_up_to_its_counts(tmp_path):
    """Positions whose vouched position (the RAIM's own solution) lies outside the geo-object were counted as ``valid``
    in statuses and left out of ``n_valid`` without a word: now ``valid_outside``, explained, and the counts add up."""
    geo = roads_along_the_berlin_drive(tmp_path)
    code, err, invoice = _process(shared(*BERLIN), geo, "--start-time", BERLIN_START, "--positioning", "snapshot", "--environment",
                                  "open", out=tmp_path / "i.json")  # fmt: skip
    assert code == 0, err
    passages = invoice["lines"] + invoice["not_charged"]
    assert any("valid_outside" in p["statuses"] for p in passages)
    for p in passages:
        assert sum(p["statuses"].values()) == p["n_inside"]
        assert p["statuses"].get("valid", 0) + p["statuses"].get("excluded_valid", 0) == p["n_valid"]
    report = tmp_path / "risk.json"
    assert run_cli("audit", str(tmp_path / "i.json"), "-q", "-o", str(report)).returncode == 0
    for item in json.loads(report.read_text()).get("revenue_at_risk", []):
        if "none valid" in item.get("cause", ""):
            assert "valid " not in item["cause"].split("none valid")[1].replace("valid_outside", "")


# ------------------------------------------------------------------------------------------------ 3. GST plausibility
def _stationary_skytraq(tmp_path: Path, seconds: int = 120) -> Path:
    """The real SkyTraq DGPS receiver's third epoch (skytraq-fixB.log, with its satellites: σ_lat 0.9, σ_lon 0.5 m beside
    an ellipse of 15.3 × 7.2 m and an RMS of 15.5 m), standing still for ``seconds`` s."""
    lines = shared("gpsd", "skytraq-fixB.log").read_text().splitlines()
    epoch = [line for line in lines[26:40] if line.startswith("$")]
    assert epoch[0].startswith("$GPGGA,182141.000") and any(line.startswith("$GPGSV") for line in epoch)
    out = []
    for k in range(seconds):
        hh, mm, ss = 18, 21 + (41 + k) // 60, (41 + k) % 60
        stamp = f"{hh:02d}{mm:02d}{ss:02d}.000"
        for line in epoch:
            body = line[1:].split("*")[0].replace("182141.000", stamp)
            out.append(_sentence(body))
    path = tmp_path / "skytraq-standing.nmea"
    path.write_text("\n".join(out) + "\n")
    return path


def _road_through(tmp_path: Path, lat: float, lon: float, length_m: float = 600.0) -> Path:
    from conftest import built_geoobjects

    d = length_m / 2 / 111_320.0
    roads = {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"id": "R1", "road_class": "motorway", "tolled": True},
                                                        "geometry": {"type": "LineString", "coordinates": [[lon - d * 1.4, lat], [lon + d * 1.4, lat]]}}]}  # fmt: skip
    (tmp_path / "roads.geojson").write_text(json.dumps(roads))
    return built_geoobjects(tmp_path / "roads.geojson", tmp_path / "geo.geojson", "--hal", "50")


def test_a_gst_that_contradicts_itself_accuses_nobody(tmp_path):
    """A stationary DGPS receiver whose GST contradicts itself was reported as spoofing (raim_persistent_alarm) from that
    sentence; now the sentence is no evidence (said per log, in the integrity summary and the invoice), no finding."""
    log = _stationary_skytraq(tmp_path)
    geo = _road_through(tmp_path, 44.0686085, -121.3145078)
    code, err, invoice = _process(log, geo, out=tmp_path / "i.json")
    assert code == 0, err
    assert invoice["findings"]["items"] == []
    assert "contradicts itself" in invoice["receiver_notes"]["gst_contradictory"] and "120 epochs" in invoice["receiver_notes"]["gst_contradictory"]
    proc = run_cli("integrity", str(log), "-o", str(tmp_path / "e.csv"), "--json")
    summary = json.loads(proc.stdout)
    assert summary["gst_rms_ignored"] == {"contradictory": 120} and "gst" not in summary["integrity_sources"]


def test_a_findings_evidence_names_its_statistic_and_threshold():
    """Every raim_persistent_alarm names the statistic it was tested with and the threshold (solution separation: the
    largest separation over its threshold, alarming above 1; null was printed)."""
    from tollcli.enforcement.findings import _alarm_statistic

    import numpy as np
    import pandas as pd

    raim = pd.DataFrame({"test_stat": [30.0, 31.0], "threshold": [np.nan, np.nan], "separation_ratio": [1.4, 1.6],
                         "test_stat_source": ["grs", "grs"]})  # fmt: skip
    got = _alarm_statistic(raim, 0, 1)
    assert got["statistic"] == "separation_ratio" and got["median_threshold"] == 1.0 and got["median_separation_ratio"] == pytest.approx(1.5)
    assert got["statistic_source"] == "grs"
    got = _alarm_statistic(raim.assign(threshold=[20.0, 22.0]), 0, 1)
    assert got["statistic"] == "test_stat" and got["median_threshold"] == 21.0


# ------------------------------------------------------------------------------------------------ 4. gpsd's JSON
def test_gpsd_json_says_what_it_lost_refuses_a_future_date_and_skips_fixes_without_time(tmp_path):
    """Through gpsd a log loses its residuals: the summary and the invoice say so. gpsd's week-rollover guess dates a
    2015 log in 2034: no invoice on that calendar. A fix without a time (Quectel EG25) is skipped and counted; it made
    ``process -`` ask for ``--date`` even when given."""
    eg25 = shared("gpsd", "quectel-eg25-g-2.log.chk")
    geo = _road_through(tmp_path, 60.02228, 30.23615)
    proc = run_cli("process", "-", "--geo", str(geo), "--tariff", TARIFF, "-o", str(tmp_path / "q.json"), "--date", "2022-09-20",
                   stdin=eg25.read_bytes())  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    invoice = json.loads((tmp_path / "q.json").read_text())
    assert "no range residuals" in invoice["receiver_notes"]["gpsd_json"]
    proc = run_cli("integrity", str(eg25), "-o", str(tmp_path / "e.csv"), "--json")
    assert "skipped 1 fixes without a time" in proc.stderr.decode()
    assert "no range residuals" in json.loads(proc.stdout)["receiver_notes"]["gpsd_json"]
    # a gpsd JSON with the receiver's residuals (u-blox prRes) lost nothing of them: no such note
    proc = run_cli("integrity", str(shared("gpsd", "ublox-zed-f9t-ubx_nmea_l5.log.chk")), "-o", str(tmp_path / "f.csv"), "--json")
    assert "receiver_notes" not in json.loads(proc.stdout)
    code, err, _ = _process(shared("gpsd", "neo-m8n.log.chk"), GEO, out=tmp_path / "n.json")
    assert code == 1 and "dated 2034-11-01, after today" in err and "week-number rollover" in err


# ------------------------------------------------------------------------------------------------ 5. nothing seen
def test_a_log_far_from_every_geoobject_says_how_far(tmp_path):
    """A real log from Oregon against the French example network: ``"lines": [], "not_charged": []`` looked like a clean
    day. Now the invoice and the summary say how close the track came (great-circle, to the nearest geo-object's box)."""
    proc = run_cli("process", str(shared("gpsd", "skytraq-fixB.log")), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / "i.json"))
    assert proc.returncode == 0, proc.stderr.decode()
    seen = json.loads((tmp_path / "i.json").read_text())["nothing_seen"]
    assert seen["boxes_overlap"] is False and 8_500_000 < seen["nearest_distance_m"] < 9_300_000  # Bend, OR – Perpignan
    assert seen["track_box_deg"][0] == pytest.approx(-121.3145, abs=1e-3)
    assert "no closer than 8,8" in proc.stderr.decode() and "outside the network's box" in proc.stderr.decode()
    _, _, near = _process(SAMPLES / "straight-drive.nmea", GEO, out=tmp_path / "near.json")
    assert "nothing_seen" not in near  # an invoice that saw geo-objects is as it was


# ------------------------------------------------------------------------------------------------ 6. geo-objects
def test_geoobjects_build_keeps_no_stretch_too_short_to_be_seen_and_names_the_real_cause(tmp_path):
    """With the defaults, roads laid along the Berlin drive gave 1 m geo-objects at HAL 5–15 m (the fallback) that charge
    a 500 m section from one position. Now: no fallback unless asked; no core shorter than a passage needs to be seen
    (N_th positions T_c apart at the section's speed: a motorway 130 km/h, 36.1 m at N_th 1); a tolled road drawn over
    another is named as the cause."""
    from test_design_hal import _write

    geo = roads_along_the_berlin_drive(tmp_path)  # (built with --hal-min 5: the operator asks for the fallback)
    assert min(f["properties"]["length_m"] for f in json.loads(geo.read_text())["features"]) >= 36.1
    out = tmp_path / "default.geojson"
    r = run_cli("geoobjects", "build", str(tmp_path / "roads.geojson"), "-o", str(out), "--json")
    # a city's streets cannot have the papers' 25 m: nothing is built, and the first section's cause is named
    assert r.returncode == 1 and "no tolled section could be built" in r.stderr.decode() and "at the roads it meets (B" in r.stderr.decode()
    r = run_cli("geoobjects", "build", str(tmp_path / "roads.geojson"), "-o", str(out), "--json", "--hal", "10-50")
    assert r.returncode == 0, r.stderr.decode()
    summary = json.loads(r.stdout)
    features = json.loads(out.read_text())["features"]
    assert features and all(f["properties"]["hal_m"] >= 10.0 and f["properties"]["length_m"] >= 36.1 for f in features)
    assert not summary["below_design_hal"] and summary["skipped"]
    assert all(re.search(r"\(B\d", s["reason"]) and s["min_core_m"] == 36.1 for s in summary["skipped"])  # the roads named
    r = run_cli("geoobjects", "build", str(tmp_path / "roads.geojson"), "-o", str(out), "--json", "--n-th", "3", "--tc", "10", "--hal", "10-50")
    assert all(f["properties"]["length_m"] >= 758.3 for f in json.loads(out.read_text())["features"]) if r.returncode == 0 else \
        "no tolled section could be built" in r.stderr.decode()  # 36.1 m/s × 21 s
    roads = _write(tmp_path / "twice.geojson", [({"id": "A", "road_class": "motorway"}, [(0, 0), (2000, 0)]),
                                                ({"id": "A-again", "road_class": "motorway"}, [(700, 0), (852, 0)])])  # fmt: skip
    r = run_cli("geoobjects", "build", str(roads), "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr.decode()
    reasons = {s["id"]: s["reason"] for s in json.loads(r.stdout)["skipped"]}
    assert "overlapped by A" in reasons["A-again"] and "the same road twice" in reasons["A-again"]


# ------------------------------------------------------------------------------------------------ 7. the map's environment
def test_receivers_that_report_only_satellites_are_charged_where_the_operator_declares_the_road_open(tmp_path):
    """A real GSA+GSV-only receiver (bu353s4.log, SiRF IV) replayed over 20 minutes along a motorway with parallel tolled
    roads 300 m away: built with the defaults nothing is charged (the urban σ: no residual says open); built with
    ``--environment motorway=open`` (the operator's declaration) every segment under the track is charged and no
    parallel one, each line recording the declaration; declared ``urban``, nothing, each passage saying why; an
    explicit ``process --environment urban`` is never weakened by an ``open`` declaration."""
    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    import process_throughput as drive

    shared("gpsd", drive.SATELLITES_ONLY_LOG)
    n = 1200
    drive.satellites_only_drive(tmp_path / "drive.nmea", n)
    (tmp_path / "roads.geojson").write_text(json.dumps(drive.roads(300, n * drive.UBLOX_SPEED)))
    under = {f"R0-{k}" for k in range(int((n - 1) * drive.UBLOX_SPEED // 250))}
    invoices = {}
    for declared in ("", "open", "urban"):
        geo = tmp_path / f"geo-{declared or 'none'}.geojson"
        r = run_cli("geoobjects", "build", str(tmp_path / "roads.geojson"), "-o", str(geo), "-q",
                    *(("--environment", f"motorway={declared}") if declared else ()))  # fmt: skip
        assert r.returncode == 0, r.stderr.decode()
        code, err, invoices[declared] = _process(tmp_path / "drive.nmea", geo, out=tmp_path / f"{declared or 'none'}.json")
        assert code == 0, err
    assert not invoices[""]["lines"] and not invoices["urban"]["lines"]
    opened = invoices["open"]
    charged = {line["geoobject"] for line in opened["lines"]}
    assert charged >= under and all(gid.startswith("R0-") for gid in charged)  # every segment under the track, no parallel
    assert all(line["environment"] == "open" and line["vouched_by"] == {"model": line["n_valid_independent"]} for line in opened["lines"])
    assert all("declared urban by the operator" in p["why"] for p in invoices["urban"]["not_charged"])
    assert invoices["urban"]["not_charged"] and all("environment" not in p for p in invoices[""]["not_charged"])
    code, _, explicit = _process(tmp_path / "drive.nmea", tmp_path / "geo-open.geojson", "--environment", "urban", out=tmp_path / "x.json")
    assert code == 0 and not explicit["lines"]
    proc = run_cli("geoobjects", "build", str(tmp_path / "roads.geojson"), "-o", str(tmp_path / "bad.geojson"), "--environment", "sunny")
    assert proc.returncode == 2 and "--environment 'sunny'" in proc.stderr.decode()


# ------------------------------------------------------------------------------------------------ 8. availability
def test_the_integrity_audit_states_availability_and_prints_no_rate_of_nothing(tmp_path):
    """``audit --epochs`` on the Berlin drive's snapshot positions (0 of 1 372 valid) printed "0 undetected (rate
    0.00e+00)" and called the unavailable epochs "alarm". Now it states the availability first; the epochs without a
    verdict are ``unavailable``, not alarms; with no positioning failure the rate is null, not 0/0."""
    epochs, report = tmp_path / "e.csv", tmp_path / "a.json"
    assert run_cli("integrity", str(shared(*BERLIN)), "--positioning", "snapshot", "-q", "-o", str(epochs)).returncode == 0
    proc = run_cli("audit", "--epochs", str(epochs), "--truth", str(shared(*BERLIN_TRUTH)), "-o", str(report), "--json")
    summary = json.loads(proc.stdout)["summary"]
    assert summary.startswith("1372 positions: 0 valid (0.0% available), 0 misleading")
    integrity = json.loads(report.read_text())["integrity"]
    assert integrity["availability"] == 0.0 and integrity["regions"]["alarm"] == 0
    assert integrity["regions"]["unavailable"] + integrity["regions"]["unavailable_failure"] == 1372
    # the truth itself as the epochs: no positioning failure, nothing to miss
    import pandas as pd

    from tollcli.charging.truth_passages import truth_trajectory

    truth = truth_trajectory(str(shared(*BERLIN_TRUTH)))
    table = truth.assign(time_utc=truth["time_utc"].dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ"), raim_status="valid", hpl_m=10.0, hal_m=50.0, p_md=5e-5)
    pd.DataFrame(table).to_csv(tmp_path / "perfect.csv", index=False)
    proc = run_cli("audit", "--epochs", str(tmp_path / "perfect.csv"), "--truth", str(shared(*BERLIN_TRUTH)), "-o", str(report), "--json")
    assert "no positioning failure to miss" in json.loads(proc.stdout)["summary"]
    assert json.loads(report.read_text())["integrity"]["undetected_rate"] is None


# ------------------------------------------------------------------------------------------------ 9. info
def _info(path, *extra) -> dict:
    proc = run_cli("info", str(path), "--json", *extra)
    assert proc.returncode == 0, proc.stderr.decode()
    return json.loads(proc.stdout)


def test_info_says_where_a_log_is_for_every_kind_and_prints_no_sentinel(tmp_path):
    """``info`` gave a pseudorange log only a row count, printed ``fix quality (GGA): -1: 34`` for a log without GGA,
    and a u-blox log with RXM-RAWX but no ephemeris failed ``process`` ("give --nav") though it holds the receiver's
    own 39 NAV-SOL fixes. Now: epochs, span, box and distance for every kind; no sentinel; the fixes read instead."""
    berlin = _info(shared(*BERLIN))
    assert berlin["epochs"] == 1372 and berlin["span_s"] == pytest.approx(282.8, abs=0.2) and berlin["clock"].startswith("seconds")
    assert berlin["box_deg"][1] == pytest.approx(52.504, abs=1e-3) and 1_500 < berlin["distance_m"] < 1_600  # test_distance_driven: its truth
    gsdc = _info(shared("gsdc2021", "Pixel4_derived.csv"))
    assert gsdc["epochs"] == 7 and gsdc["first_utc"].startswith("2020-05-14") and gsdc["box_deg"]
    nmea = _info(SAMPLES / "straight-drive.nmea")
    assert nmea["distance_m"] == pytest.approx(179 * 13.9, rel=0.02) and nmea["box_deg"][1] == pytest.approx(42.698, abs=0.01)
    magellan = _info(shared("gpsd", "magellan-ec10.log"))  # RMC, no GGA
    assert "-1" not in magellan["fix_quality"]
    assert "-1:" not in run_cli("info", str(shared("gpsd", "magellan-ec10.log"))).stdout.decode()
    m8t = shared("gpsd", "ublox-neo-m8t.log")
    info = _info(m8t)
    assert info["epochs"] == 39 and "NAV-SOL" in info["positions"] and "read instead" in info["positions"]
    assert "/tmp/" not in info["positions"] or str(m8t).startswith("/tmp/")
    code, err, invoice = _process(m8t, GEO, out=tmp_path / "m8t.json")
    assert code == 0, err
    assert invoice["parameters"]["positioning_used"] == "receiver" and "NAV-SOL" in invoice["parameters"]["positioning_note"]
    proc = run_cli("integrity", str(m8t), "-o", str(tmp_path / "m8t.csv"), "--json")
    assert proc.returncode == 0 and json.loads(proc.stdout)["epochs"] == 39


# ------------------------------------------------------------------------------------------------ 10. exit codes, batch
def test_exit_codes_as_documented_and_batch_checks_what_its_logs_share_once(tmp_path):
    """``batch`` with a missing --geo or --tariff exited 4 (process: 2), --geo naming a folder 1; a tariff typo failed
    every log of a fleet run one by one. README: 2 is a missing file or a folder where a file was expected."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a", "b"):
        (logs / f"{name}.nmea").write_bytes((SAMPLES / "straight-drive.nmea").read_bytes())
    bad = tmp_path / "bad.toml"
    bad.write_text('currency = "EUR"\n[road_class.motorway]\ncar = "x"\n')
    for command in (("process", str(logs / "a.nmea")), ("batch", str(logs))):
        out = ("-o", str(tmp_path / f"{command[0]}.json")) if command[0] == "process" else ("-o", str(tmp_path / "out"))
        for geo, tariff, code, words in ((str(tmp_path / "missing.geojson"), TARIFF, 2, "no such file"),
                                         (GEO, str(tmp_path / "missing.toml"), 2, "no such file"),
                                         (str(tmp_path), TARIFF, 2, "is a directory"),
                                         (GEO, str(tmp_path), 2, "is a directory"),
                                         (GEO, str(bad), 1, "car: not a number")):  # fmt: skip
            proc = run_cli(*command, "--geo", geo, "--tariff", tariff, *out, "-q")
            err = proc.stderr.decode()
            assert proc.returncode == code and words in err and err.count("\n") == 1, (command, geo, tariff, err)
    assert not (tmp_path / "out").exists()  # refused before any log: no output folder, no failed/ per log


# ------------------------------------------------------------------------------------------------ 11. tariff keys
def test_a_vehicle_class_typo_in_a_tariff_is_an_error_naming_its_line(tmp_path):
    """``vna = 1.40`` was accepted; only a van log failed later, naming neither the line nor the key."""
    typo = tmp_path / "typo.toml"
    typo.write_text('currency = "EUR"\n[road_class.motorway]\ncar = 0.95\nvna = 1.40\n')
    code, err, _ = _process(SAMPLES / "straight-drive.nmea", GEO, tariff=typo, out=tmp_path / "i.json")
    assert code == 1 and f"{typo}:4: [road_class.motorway] vna: unknown vehicle class (did you mean van?)" in err
    own = tmp_path / "own.toml"
    own.write_text('currency = "EUR"\nvehicle_classes = ["car", "bus"]\n[road_class.motorway]\ncar = 0.95\nbus = 1.10\n')
    code, err, invoice = _process(SAMPLES / "straight-drive.nmea", GEO, "--vehicle-class", "bus", tariff=own, out=tmp_path / "c.json")
    assert code == 0 and invoice["total"] == "2.20", err
    own.write_text('currency = "EUR"\nvehicle_classes = ["car"]\n[road_class.motorway]\ncar = 0.95\nvan = 1.10\n')
    code, err, _ = _process(SAMPLES / "straight-drive.nmea", GEO, tariff=own, out=tmp_path / "d.json")
    assert code == 1 and ":5: [road_class.motorway] van: unknown vehicle class" in err


# ------------------------------------------------------------------------------------------------ 12. small ones
def test_small_ones(tmp_path):
    """``--date yesterday`` said "Value error"; batch's help called the urban switch twofold; geoobjects/README.md said
    the folder was empty; the audit listed a finding twice for two invoices of the same log."""
    proc = run_cli("process", str(SAMPLES / "straight-drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "--date", "yesterday", "-o",
                   str(tmp_path / "x.json"))  # fmt: skip
    assert proc.returncode == 2 and "Value error" not in proc.stderr.decode() and "'yesterday'" in proc.stderr.decode()
    assert "twofold" not in run_cli("batch", "--help").stdout.decode()
    assert "Empty until" not in (REPO / "geoobjects" / "README.md").read_text()
    log = shared("gpsd", "sl869.log")  # a real receiver with a one-epoch position glitch: one finding
    for k, extra in enumerate(((), ("--n-th", "2"))):
        assert run_cli("process", str(log), "--geo", GEO, "--tariff", TARIFF, "-o", str(tmp_path / f"{k}.json"), "-q", *extra).returncode == 0
    report = tmp_path / "risk.json"
    assert run_cli("audit", str(tmp_path / "0.json"), str(tmp_path / "1.json"), "-q", "-o", str(report)).returncode == 0
    findings = json.loads(report.read_text())["findings"]
    assert len(findings) == 1 and findings[0]["kind"] == "position_jump"


def test_integrity_names_an_unknown_environment(tmp_path):
    proc = run_cli("integrity", str(shared("gpsd", "skytraq.log")), "-o", str(tmp_path / "e.csv"), "--json")
    summary = json.loads(proc.stdout)
    assert "" not in summary["environments"] and summary["environments"].get("unknown")
    assert re.search(r"environment \d+ unknown", run_cli("integrity", str(shared("gpsd", "skytraq.log")), "-o",
                                                          str(tmp_path / "f.csv")).stderr.decode())  # fmt: skip
