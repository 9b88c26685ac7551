"""``process`` on a sliding tail (tollcli.job.streaming): the same invoice as the whole log at once,
in memory that does not grow with the log.

The reference is the same charger with ``rounds=False`` (every chunk kept, everything done once at
the end: the whole-log computation). The streamed runs use 37-epoch chunks and a round after every
chunk, so that chunk edges, frontiers, open findings and open passages fall everywhere.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, SAMPLES
from hypothesis import given, settings
from hypothesis import strategies as st

from tollcli.geoobjects.build import build_geoobjects
from tollcli.charging.invoice import invoice_json
from tollcli.charging.recognition import _charges_in_order, charges, passages
from tollcli.enforcement.trip import trailing_median
from tollcli.integrity.map_matching import MatchParams, load_roads, match_with_trace
from tollcli.job import pipeline, streaming
from tollcli.job.pipeline import ChargeSettings, charge_log
from tollcli.readers.nmea import read_nmea

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
ROADS = str(REPO / "geoobjects" / "example-roads.geojson")
LOGS = ["sim/urban-fault/drive.nmea", "sim/rural-fault/drive.nmea", "sim/urban-clean/drive.nmea", "straight-drive.nmea",
        "sim/urban-fault/drive-derived.csv", "sim/rural-clean/drive-derived.csv"]  # the last two: pseudorange logs


def _whole(monkeypatch, log: str, **kw) -> dict:
    monkeypatch.setattr(pipeline, "STREAM_ROUNDS", False)
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 1_000_000)
    try:
        return charge_log(log, GEO, TARIFF, ChargeSettings(**kw.pop("settings", {})), **kw)[0]
    finally:
        monkeypatch.setattr(pipeline, "STREAM_ROUNDS", True)


def _streamed(monkeypatch, log: str, chunk: int = 37, **kw) -> dict:
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", chunk)
    monkeypatch.setattr(pipeline, "BLOCK_BYTES", 2048)  # chunks end at block ends
    monkeypatch.setattr(streaming, "ROUND_ROWS", 1)
    return charge_log(log, GEO, TARIFF, ChargeSettings(**kw.pop("settings", {})), **kw)[0]


@pytest.mark.parametrize("log", LOGS)
@pytest.mark.parametrize("roads", [None, ROADS])
def test_streamed_invoice_is_the_whole_log_invoice(monkeypatch, log, roads):
    path = str(SAMPLES / log)
    whole = _whole(monkeypatch, path, roads=roads)
    streamed = _streamed(monkeypatch, path, roads=roads)
    assert invoice_json(streamed) == invoice_json(whole)
    assert whole["lines"] or whole["not_charged"]  # the comparison covers passages
    if roads:  # the derived CSV has no speeds: RAIM alone
        assert whole["parameters"]["policy_used"] == ("raim" if log.endswith(".csv") else "all")


def test_a_real_pseudorange_drive_streamed_is_the_whole_log(tmp_path, monkeypatch):
    """The Berlin drive (libRSF pseudoranges and odometry speed, 1 372 epochs) through the one charge path in 37-epoch
    chunks, with 500 m roads laid along its own track: the invoice of the whole log, passages and findings included,
    with the smoothed trajectory (the default) and with snapshot positions — the streamed run also solving its snapshot
    positions 100 epochs at a time and sweeping its trajectory in 300-epoch chunks (what a long log gets)."""
    from conftest import BERLIN_START, roads_along_the_berlin_drive, shared

    from tollcli.gnss import pseudorange_wls
    from tollcli.integrity import trajectory_sweep

    log = str(shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt"))
    geo = roads_along_the_berlin_drive(tmp_path)
    for chosen in ({}, {"positioning": "snapshot"}, {"environment": "open", "positioning": "snapshot"}):
        chosen = {**chosen, "start_time": BERLIN_START}
        monkeypatch.setattr(pipeline, "STREAM_ROUNDS", False)
        monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 1_000_000)
        monkeypatch.setattr(pseudorange_wls, "BLOCK_EPOCHS", 1_000_000)
        monkeypatch.setattr(trajectory_sweep, "CHUNKED_FROM_EPOCHS", 1_000_000)
        whole = charge_log(log, str(geo), TARIFF, ChargeSettings(**chosen))[0]
        monkeypatch.setattr(pipeline, "STREAM_ROUNDS", True)
        monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 37)
        monkeypatch.setattr(streaming, "ROUND_ROWS", 1)
        monkeypatch.setattr(pseudorange_wls, "BLOCK_EPOCHS", 100)
        monkeypatch.setattr(trajectory_sweep, "CHUNKED_FROM_EPOCHS", 500)
        monkeypatch.setattr(trajectory_sweep, "CHUNK_EPOCHS", 300)
        streamed = charge_log(log, str(geo), TARIFF, ChargeSettings(**chosen))[0]
        assert invoice_json(streamed) == invoice_json(whole)
        if "positioning" not in chosen:  # the smoothed trajectory: the city positions charge
            assert whole["lines"] and whole["parameters"]["positioning_used"] == "smoothed"
        else:  # each epoch alone: mostly not (declared open: some)
            assert whole["not_charged"] and whole["findings"]["items"]
    assert whole["lines"]  # declared open, the city positions charge


def test_rounds_do_happen_and_the_tail_stays_short(tmp_path, monkeypatch):
    """A round after every chunk, and what the tail keeps is bounded by the chunk and the context, not the log."""
    from tollcli.readers.nmea.compose import straight_drive

    log = tmp_path / "drive.nmea"
    log.write_text("\n".join(straight_drive(3_000)) + "\n")
    sizes = []
    real_round = streaming.TailCharger._round

    def spy(self, final):
        real_round(self, final)
        sizes.append((final, len(self.epochs), self.committed))

    monkeypatch.setattr(streaming.TailCharger, "_round", spy)
    invoice = _streamed(monkeypatch, str(log), chunk=100, roads=ROADS)
    assert invoice_json(invoice) == invoice_json(_whole(monkeypatch, str(log), roads=ROADS))
    rounds = [s for s in sizes if not s[0]]
    assert len(rounds) > 20
    bound = 100 + streaming.LOOKAHEAD_ROWS + streaming.CONTEXT_ROWS + 200  # chunk + look-ahead + context (≤ 90 s at 1 Hz + fixes)
    assert max(n for _, n, _ in rounds) <= bound
    assert sizes[-1][2] == 3_000 > 5 * bound  # the log is much longer than the tail


def _trip_log(tmp_path, name: str, **trip) -> str:
    from test_enforcement import _trip, _write

    return _write(tmp_path / f"{name}.nmea", *_trip(300, **trip))


@pytest.mark.parametrize(
    ("kind", "trip"),
    [
        ("gap", dict(drop=(100.0, 200.0))),
        ("cn0_collapse", dict(jam_at_s=[100.0], jam_duration_s=40.0, jam_db=12.0, track_min_dbhz=15.0)),
        ("fix_lost_at_speed", dict(jam_at_s=[100.0], jam_duration_s=30.0, jam_db=25.0)),
        ("cn0_uniform", dict(cn0_dbhz=48.0)),
        ("raim_persistent_alarm", "fault"),
        ("overspeed", "overspeed"),
        ("doppler_mismatch", "doppler"),
    ],
)
def test_findings_across_chunk_edges_are_the_whole_log_findings(tmp_path, monkeypatch, kind, trip):
    """Each kind of finding, cut by chunk edges and frontiers everywhere, comes out as the whole log gives it."""
    from test_enforcement import _speed

    from tollcli.simulate.errors import FaultPlan

    if isinstance(trip, str):
        trip = {"fault": dict(faults=FaultPlan(bias_m=150.0, at_s=[100.0], duration_s=60.0)),
                "overspeed": dict(edit=_speed(90.0, 100, 106)), "doppler": dict(edit=_speed(7.0, 100, 140))}[trip]  # fmt: skip
    log = _trip_log(tmp_path, kind, **trip)
    whole = _whole(monkeypatch, log)
    assert kind in {f["kind"] for f in whole["findings"]["items"]}
    for chunk in (13, 37, 101):
        streamed = _streamed(monkeypatch, log, chunk=chunk)
        assert streamed["findings"] == whole["findings"], chunk
        assert invoice_json(streamed) == invoice_json(whole)


def test_match_restarts_exactly_at_any_row():
    """Matching rows r… from the trace's restart state gives what matching the whole table gives for them."""
    epochs = read_nmea(str(SAMPLES / "sim" / "urban-fault" / "drive.nmea")).epochs
    roads = load_roads(ROADS)
    rng = np.random.default_rng(5)
    trusted = rng.random(len(epochs)) > 0.2
    full, trace = match_with_trace(epochs, roads, MatchParams(), trusted)
    assert trace.run_start.size > 3 and (full["matched_road"] != "").sum() > 100
    for row in sorted(set(rng.integers(1, len(epochs) - 1, 25).tolist()) | set(trace.run_start[1:4].tolist())):
        start, state = trace.restart(row)
        assert start <= row
        part, _ = match_with_trace(epochs.iloc[start:].reset_index(drop=True), roads, MatchParams(), trusted[start:], state)
        pd.testing.assert_frame_equal(part, full.iloc[start:].reset_index(drop=True))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 400), st.booleans()), min_size=1, max_size=60))
def test_charges_without_groupby_are_the_groupby_ones(rows):
    """The grouping of passages done in numpy equals pandas' groupby on random positions."""
    geo = SimpleNamespace(ids=np.array(["A1", "A2", "B", "C"], dtype=object), gap_times_s=lambda: np.zeros(4))  # passages() needs the ids and tunnel/gap times
    obj = np.array([r[0] for r in rows])
    t_s = 1.7e9 + np.array([r[1] for r in rows], float)
    cols = {"epoch_row": np.arange(len(rows)), "obj": obj, "raim_status": np.full(len(rows), "valid", object),
            "test_stat": np.ones(len(rows)), "threshold": np.ones(len(rows)), "p_fa": np.ones(len(rows)),
            "test_stat_source": np.full(len(rows), "grs", object), "integrity_source": np.full(len(rows), "grs", object), "valid": np.array([r[2] for r in rows]),
            "verdict": np.full(len(rows), "valid", object), "t_s": t_s,
            "time_utc": pd.to_datetime(t_s * 1000, unit="ms", utc=True).array}  # fmt: skip
    pos = passages(cols, geo, tc_s=5.0, passage_gap_s=60.0)
    fast = _charges_in_order(pos)
    assert fast is not None
    grouped = pos.groupby(["geoobject", "passage"], sort=False).agg(
        entry_utc=("time_utc", "min"), exit_utc=("time_utc", "max"), n_inside=("valid", "size"),
        n_valid=("valid", "sum"), n_independent=("independent", "sum")).reset_index()  # fmt: skip
    pd.testing.assert_frame_equal(fast, grouped)
    shuffled = pos.sample(frac=1.0, random_state=1).reset_index(drop=True)
    if len(shuffled) > 1 and not shuffled["passage"].is_monotonic_increasing:
        assert _charges_in_order(shuffled) is None or len(set(shuffled["passage"])) == len(shuffled)
    pd.testing.assert_frame_equal(charges(shuffled, 1).sort_values(["entry_utc", "geoobject"]).reset_index(drop=True),
                                  charges(pos, 1))  # fmt: skip


def test_trailing_median_of_columns_is_each_column_alone():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.choice([0.5, 1.0, 1.0, 2.0], 400))
    values = rng.normal(40, 5, (400, 3))
    values[rng.random((400, 3)) < 0.1] = np.nan
    for times in (t, t[::-1].copy()):  # increasing, and not (epoch-count windows)
        together = trailing_median(values, times, 30.0)
        for k in range(3):
            np.testing.assert_array_equal(together[:, k], trailing_median(values[:, k], times, 30.0))


def _synthetic_trip(tmp_path, n: int, seed: int):
    """Per-epoch tables of a drive on road P (a parallel, unconnected road T lies 60 m west) with episodes:
    fixes pushed next to T, RAIM alarms, an overspeed, a C/N0 drop, a fix loss and a time gap."""
    from test_map_matching import _drive, _roads

    rng = np.random.default_rng(seed)
    at = lambda: int(rng.integers(0, n - 40))  # noqa: E731
    east = np.full(n, 60.0)
    a = at()
    east[a : a + int(rng.integers(20, 150))] = 5.0  # biased towards T: the match must stay on P
    epochs = _drive(east, seconds=n, speed=4.0)  # 2.4 km: on the 3.1 km roads throughout
    epochs["time_utc"] = epochs["time_utc"] + pd.to_timedelta(np.where(np.arange(n) >= at(), 90.0, 0.0), unit="s")
    epochs.insert(0, "epoch", np.arange(n))
    epochs["tod_s"] = (epochs["time_utc"] - epochs["time_utc"].dt.normalize()).dt.total_seconds()
    epochs["line"] = np.arange(n) * 9
    fix = np.ones(n, bool)
    a = at()
    fix[a : a + int(rng.integers(1, 30))] = False
    epochs["fix_valid"] = fix
    epochs.loc[max(a - 3, 0) : a, "speed_mps"] = 12.0  # reported fast just before: a fix lost at speed
    epochs["n_used"] = 8
    epochs["hdop"] = 0.9
    speed = epochs["speed_mps"].to_numpy().copy()
    a = at()
    speed[a : a + int(rng.integers(1, 8))] = 90.0  # reported only (the positions go on at 4 m/s)
    epochs["speed_mps"] = speed
    epochs["sigma_major_m"] = 3.0
    epochs["pos_disagreement_m"] = np.nan
    epochs["date_disagreement_days"] = np.nan
    status = np.where(rng.random(n) < 0.05, "fault_detected", "valid").astype(object)
    a = at()
    b = a + int(rng.integers(10, 80))
    status[a:b] = "fault_detected"
    b += int(rng.integers(1, 12))  # a short pause, then the alarm again: one persistent-alarm episode or two
    status[b : b + int(rng.integers(5, 60))] = "fault_detected"
    raim = pd.DataFrame({"raim_status": status, "n_used": 8, "test_stat": rng.chisquare(4, n), "threshold": 13.0})
    med = rng.normal(42.0, 0.5, n)
    a = at()
    med[a : a + int(rng.integers(2, 30))] -= 15.0
    cn0 = pd.DataFrame({"n_tracked": np.full(n, 9), "cn0_median": med, "cn0_p80": med + 3.0, "cn0_std": np.full(n, 4.0)})
    rows = np.sort(rng.choice(n, size=n // 3, replace=False))
    pairs = {"epoch_row": rows, "obj": np.zeros(rows.size, np.int64), "raim_status": status[rows],
             "test_stat": rng.random(rows.size), "threshold": np.full(rows.size, 13.0), "p_fa": np.full(rows.size, 1e-3),
             "test_stat_source": np.full(rows.size, "grs", object), "integrity_source": np.full(rows.size, "grs", object), "raim_valid": status[rows] == "valid"}  # fmt: skip
    _roads(tmp_path, connector=False)
    roads = tmp_path / "roads.geojson"
    geo = tmp_path / "geo.geojson"  # one geo-object: around T (P is free), so a position counts only when matched to T
    geo.write_text(json.dumps(build_geoobjects(str(roads))))
    return epochs, raim, cn0, pairs, str(roads), str(geo)


def _charge(epochs, raim, cn0, pairs, roads, geo, cuts, rounds):
    from tollcli.charging.recognition import load_geoobjects

    charger = streaming.TailCharger(load_geoobjects(geo), ChargeSettings(policy="all"), roads, rounds=rounds)
    edges = [0, *sorted(set(cuts)), len(epochs)]
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi > lo:
            part = pairs["epoch_row"]
            sel = (part >= lo) & (part < hi)
            charger.add(epochs.iloc[lo:hi], raim.iloc[lo:hi], cn0.iloc[lo:hi], {k: v[sel] for k, v in pairs.items()})
    return charger.finish()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.lists(st.integers(1, 599), max_size=40))
def test_tail_charger_on_random_episodes_and_cuts(tmp_path_factory, seed, cuts):
    """Random episodes (biased fixes next to an unconnected road, alarms, overspeed, C/N0 drop, fix loss,
    a forward time jump) and random chunk edges: the streamed result is the whole-table one."""
    tmp_path = tmp_path_factory.mktemp("trip")
    tables = _synthetic_trip(tmp_path, 600, seed)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(streaming, "ROUND_ROWS", 1)
        got = _charge(*tables, cuts, rounds=True)
    want = _charge(*tables, [], rounds=False)
    assert got[0] == want[0] == "all"
    pd.testing.assert_frame_equal(got[1].drop(columns="passage"), want[1].drop(columns="passage"))
    assert sorted(got[2][0].values(), key=str) == sorted(want[2][0].values(), key=str)
    assert got[3] == want[3]
    assert got[4] == want[4]


def test_an_epoch_without_speed_streamed_is_the_whole_log(tmp_path, monkeypatch):
    """A speed missing in one early epoch: the streamed invoice is still the whole log's (the gap stays local)."""
    from tollcli.readers.nmea.fields import checksum

    lines = (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()
    at = [i for i, line in enumerate(lines) if line[3:6] == "RMC"][3]
    for i, fields in ((at, (7,)), (at + 1, (5, 7))):  # the epoch's RMC and VTG
        f = lines[i][1 : lines[i].rfind("*")].split(",")
        for k in fields:
            f[k] = ""
        body = ",".join(f)
        lines[i] = f"${body}*{checksum(body):02X}"
    log = tmp_path / "drive.nmea"
    log.write_text("\n".join(lines) + "\n")
    whole = _whole(monkeypatch, str(log))
    assert invoice_json(_streamed(monkeypatch, str(log))) == invoice_json(whole)
    assert len(whole["lines"]) == 2


@pytest.mark.parametrize("log, kind, positioning", [(("smartloc", "Berlin_Potsdamer_Platz_Input.txt"), "librsf", "auto"),
                                                    (("smartloc", "Berlin_Potsdamer_Platz_Input.txt"), "librsf", "snapshot"),
                                                    (("rtklibexplorer", "gnss_1730.ubx"), "ubx", "auto"),
                                                    ("rural-fault", "gsdc-derived", "snapshot")])  # fmt: skip
def test_a_pseudorange_logs_integrity_table_checked_in_chunks_is_the_whole_logs(monkeypatch, log, kind, positioning):
    """``integrity`` of a pseudorange log runs the RAIM and the measured environment a chunk of epochs at a time (the
    RAIM over all 40 000 epochs of a long drive at once was its peak memory): in chunks of 37 epochs, the table of the
    whole log at once, to the bit — real logs with the trajectory and with snapshot positions, and a simulated drive
    with a faulty satellite (valid, fault_detected and unavailable epochs; open and urban measured)."""
    from conftest import shared

    from tollcli.integrity.raim import RaimParams
    from tollcli.job import log_integrity

    path = str(SAMPLES / "sim" / log / "drive-derived.csv") if isinstance(log, str) else str(shared(*log))

    def table(chunk_epochs):
        monkeypatch.setattr(log_integrity, "RAIM_CHUNK_EPOCHS", chunk_epochs)
        parts = [c.table for c in log_integrity.iter_integrity(path, kind, RaimParams(hal_m=50.0), positioning=positioning)]
        return parts, pd.concat(parts, ignore_index=True)

    whole_parts, whole = table(1_000_000)
    chunked_parts, chunked = table(37)
    assert len(whole_parts) == 1 and len(chunked_parts) == -(-len(whole) // 37) > 5
    pd.testing.assert_frame_equal(chunked, whole, check_exact=True)
    assert chunked_parts[0].attrs == whole_parts[0].attrs
    if kind == "gsdc-derived":  # verdicts that differ among the epochs, and both environments, are compared
        assert whole["raim_status"].nunique() == 3 and whole["environment"].nunique() == 2
