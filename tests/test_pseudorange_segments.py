"""A libRSF log read in blocks and placed segment by segment (``tollcli/job/pseudorange_segments.py``).

What must hold: the blocks are the whole file's rows, malformed lines counted and named as before; a log of one segment
(every real one in ../shared/data) is placed exactly as before segments existed; a longer one keeps every epoch once, in
order, numbered on, each within its bound against the truth; a segment written to disk comes back the same; a log
out of time order is read whole; nothing is left on disk.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pandas as pd
import pytest
from conftest import shared

from tollcli.errors import DataError
from tollcli.geodesy import geodetic2enu
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity.trajectory import with_trajectory
from tollcli.job import pseudorange_segments as segments
from tollcli.readers.librsf import iter_librsf, librsf_truth, read_librsf

BERLIN = "smartloc", "Berlin_Potsdamer_Platz_Input.txt"


def _placed(path: str, positioning: str = "auto", chunk_epochs: int = 700):
    with segments.placed_log(path, "librsf", None, "nominal", 5.0, NominalModel(), False, positioning) as placed:
        parts = list(placed.chunks(chunk_epochs))
        folder = placed._folder
    assert folder is None or not os.path.exists(folder)  # the stored segments are gone once the log is placed
    return placed, parts


def _same_measurements(a, b) -> None:
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert (x is None) == (y is None), f.name
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            assert (x == y).all() if x.dtype == object else np.array_equal(x, y, equal_nan=True), f.name


def test_the_blocks_are_the_whole_files_rows_even_past_a_malformed_line(tmp_path):
    """Real Berlin drive, with a field that is no number in its 15 000th line: read in blocks of 4 000 rows (the
    blocks from the bad one on read as text) the tables, the malformed count and the strict error's line are the
    whole file's."""
    lines = shared(*BERLIN).read_text().splitlines(keepends=True)
    lines[14_999] = lines[14_999].replace(lines[14_999].split()[2], "12x34.5", 1)
    bad = tmp_path / "bad.txt"
    bad.write_text("".join(lines))
    for path in (str(shared(*BERLIN)), str(bad)):
        whole = read_librsf(path)
        parts = list(iter_librsf(path, block_rows=4_000))
        assert len(parts) > 3
        for table in ("pseudoranges", "odometry", "points"):
            pd.testing.assert_frame_equal(pd.concat([getattr(p, table) for p in parts], ignore_index=True), getattr(whole, table))
        assert sum(p.malformed for p in parts) == whole.malformed == (path == str(bad))
    with pytest.raises(DataError) as whole_error:
        read_librsf(str(bad), strict=True)
    with pytest.raises(DataError) as block_error:
        list(iter_librsf(str(bad), strict=True, block_rows=4_000))
    assert str(block_error.value) == str(whole_error.value)
    assert f"{bad}:15000:" in str(block_error.value)


def test_a_log_of_one_segment_is_placed_as_before():
    """The real Berlin drive (1 372 epochs) is one segment: its placed epochs and measurements are, to the bit, those of
    the log read and solved whole and placed by the trajectory estimator — chunked as the caller asks."""
    path = str(shared(*BERLIN))
    epochs, meas, used = with_trajectory(*pseudorange_epochs(path, "librsf", None, "nominal", 5.0, NominalModel()), "auto")
    placed, parts = _placed(path)
    assert (placed.segments, placed.positioning, used) == (1, "smoothed", "smoothed")
    assert [len(p) for p, _ in parts] == [700, 672]
    pd.testing.assert_frame_equal(pd.concat([p for p, _ in parts], ignore_index=True), epochs)
    rows = np.arange(700, len(epochs))
    _same_measurements(parts[1][1], meas.take(rows))
    assert placed.correlation_s == epochs.attrs["trajectory_correlation_s"]
    assert parts[0][0].attrs["skipped_lines"] == 0


@pytest.fixture(scope="module")
def long_drive(tmp_path_factory):
    """A simulated city drive (reflections, odometry with its errors) of 2 400 s at 1 Hz, 24 km straight on."""
    from tollcli.simulate.drive import SimConfig
    from tollcli.simulate.route import straight
    from tollcli.simulate.run import write_drive

    folder = tmp_path_factory.mktemp("long")
    write_drive(straight(48.137, 11.575, 30.0, 10.0, 2_400.0, 1.0), SimConfig(env="urban", nlos=True, odometry=True, seed=5), str(folder))
    return folder


@pytest.mark.parametrize("size", [(600, 600.0, 150), (400, 400.0, 100)])
def test_a_long_log_is_placed_in_segments_each_epoch_once_within_its_bound(long_drive, monkeypatch, size):
    """Cut into segments (cores of 600 or 400 epochs and seconds, margins of 150 or 100), the 2 400-epoch drive keeps
    every epoch once, in order, numbered on from 0, at its own time; every position is within its bound against the
    simulator's truth (as whole: 0 misleading), and every epoch stays valid at HAL 50 m."""
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", size[0])
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", size[1])
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", size[2])
    path = str(long_drive / "drive-librsf.txt")
    placed, parts = _placed(path)
    epochs = pd.concat([p for p, _ in parts], ignore_index=True)
    whole = pseudorange_epochs(path, "librsf", None, "nominal", 5.0, NominalModel())[0]
    assert placed.segments == 2_400 // size[0]  # the last core takes the rest: never a short one
    assert placed.positioning == "smoothed" and placed.note is None
    assert (epochs["epoch"].to_numpy() == np.arange(len(whole))).all()
    assert (epochs["time_utc"].to_numpy() == whole["time_utc"].to_numpy()).all()
    assert (epochs["positioning"] == "smoothed").all()
    hpl = np.concatenate([m.trajectory_hpl_m for _, m in parts])
    truth = librsf_truth(str(long_drive / "truth-librsf.txt")).set_index("time_utc").reindex(epochs["time_utc"])
    zero = np.zeros(len(epochs))
    e, n, _ = geodetic2enu(epochs["lat_deg"].to_numpy(), epochs["lon_deg"].to_numpy(), zero, truth["lat_deg"].to_numpy(),
                           truth["lon_deg"].to_numpy(), zero)  # fmt: skip
    hpe = np.hypot(e, n)
    assert np.isfinite(hpe).all() and (hpe < hpl).all() and (hpl < 50.0).all()
    assert np.percentile(hpe, 95) < 10.0


def test_a_stored_segment_comes_back_the_same(tmp_path):
    """The arrays a segment is stored as give back its epoch table (its dtypes: UTC times in µs, text, int16) and every
    measurement array, text ones included, to the bit — and no pickle is read."""
    path = str(shared(*BERLIN))
    epochs, meas, _ = with_trajectory(*pseudorange_epochs(path, "librsf", None, "nominal", 5.0, NominalModel()), "auto")
    segments._store(str(tmp_path / "s"), epochs, meas)
    back, back_meas = segments._load(str(tmp_path / "s"))
    back.attrs = epochs.attrs
    pd.testing.assert_frame_equal(back, epochs)
    _same_measurements(back_meas, meas)


def test_a_log_out_of_time_order_is_read_whole(tmp_path, monkeypatch):
    """Berlin with its last epoch's lines moved to the top cannot be cut by time: it is placed whole, as before."""
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 300)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 60.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 50)
    lines = shared(*BERLIN).read_text().splitlines(keepends=True)
    last = lines[-1].split()[1]
    tail = [line for line in lines if line.split()[1] == last]
    shuffled = tmp_path / "shuffled.txt"
    shuffled.write_text("".join(tail + [line for line in lines if line.split()[1] != last]))
    placed, parts = _placed(str(shuffled))
    assert placed.segments == 1
    epochs, _, _ = with_trajectory(*pseudorange_epochs(str(shuffled), "librsf", None, "nominal", 5.0, NominalModel()), "auto")
    pd.testing.assert_frame_equal(pd.concat([p for p, _ in parts], ignore_index=True), epochs)


def test_nothing_is_left_on_disk_when_the_reader_stops_midway(long_drive, monkeypatch):
    """A caller that stops after the first chunk (an error of its own) leaves no stored segment behind."""
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 600)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 600.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 150)
    with pytest.raises(RuntimeError):
        with segments.placed_log(str(long_drive / "drive-librsf.txt"), "librsf", None, "nominal", 5.0, NominalModel(), False,
                                 "auto") as placed:  # fmt: skip
            folder = placed._folder
            assert os.path.isdir(folder) and len(os.listdir(folder)) == 4
            for _ in placed.chunks(100):
                raise RuntimeError("the caller's own error")
    assert not os.path.exists(folder)


def _roads_along(truth: pd.DataFrame, path, offset_m: float) -> None:
    """Tolled roads: the drive's own straight line cut into four sections, and a parallel ``offset_m`` to its left."""
    from tollcli.geodesy import enu_shift2geodetic

    lat, lon = truth["lat_deg"].to_numpy(), truth["lon_deg"].to_numpy()
    e, n, _ = geodetic2enu(lat, lon, np.zeros(lat.size), lat[0], lon[0], 0.0)
    d = np.array([e[-1], n[-1]]) / np.hypot(e[-1], n[-1])
    left = np.array([-d[1], d[0]]) * offset_m
    cuts = np.linspace(0, lat.size - 1, 5).astype(int)
    features = []
    for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        for name, shift in ((f"DRIVEN{k}", np.zeros(2)), (f"PARALLEL{k}", left)):
            la, lo = enu_shift2geodetic(lat[0], lon[0], e[[a, b]] + shift[0], n[[a, b]] + shift[1])
            features.append({"type": "Feature", "properties": {"id": name, "road_class": "primary"},
                             "geometry": {"type": "LineString", "coordinates": [[lo[0], la[0]], [lo[1], la[1]]]}})  # fmt: skip
    path.write_text(__import__("json").dumps({"type": "FeatureCollection", "features": features}))


def test_a_long_log_placed_in_segments_is_charged_for_the_road_driven_and_the_same_in_any_chunks(long_drive, tmp_path, monkeypatch):
    """Metamorphic: the 2 400 s drive placed in four segments is charged each of the four sections it drove, once, and
    not the parallel road 150 m away — as placed whole; and charging it 3 600 or 333 epochs at a time gives the same
    invoice, byte for byte."""
    import json

    from conftest import BERLIN_START, run_cli

    from tollcli.job import pipeline

    roads, geo, tariff = tmp_path / "roads.geojson", tmp_path / "geo.geojson", tmp_path / "t.toml"
    _roads_along(librsf_truth(str(long_drive / "truth-librsf.txt")), roads, 150.0)
    assert run_cli("geoobjects", "build", str(roads), "-o", str(geo), "--hal", "50", "-q").returncode == 0
    tariff.write_text('currency = "EUR"\n[road_class.primary]\ncar = 1.00\n')
    settings = pipeline.ChargeSettings(start_time=BERLIN_START)
    log = str(long_drive / "drive-librsf.txt")

    def charged() -> tuple[list[str], str]:
        invoice, _ = pipeline.charge_log(log, str(geo), str(tariff), settings)
        return sorted(line["geoobject"] for line in invoice["lines"]), json.dumps(invoice, sort_keys=True)

    whole, _ = charged()
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 600)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 600.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 150)
    in_segments, invoice = charged()
    monkeypatch.setattr(pipeline, "CHUNK_EPOCHS", 333)
    _, small_chunks = charged()
    assert whole == in_segments == ["DRIVEN0", "DRIVEN1", "DRIVEN2", "DRIVEN3"]
    assert small_chunks == invoice
    assert json.loads(invoice)["parameters"]["positioning_used"] == "smoothed"


def test_a_gsdc_derived_csv_is_read_in_blocks_and_placed_in_segments(long_drive, tmp_path, monkeypatch):
    """GSDC derived CSVs the same way: the real GSDC 2021 file (and the simulated drive's, with a row whose pseudorange
    is no number) read in blocks are the whole file's rows and lines, malformed rows counted and named alike; a log of
    one segment placed to the bit as before; the simulated drive in four segments, without odometry (the GNSS-only
    motion model), every epoch once and within its bound against the truth."""
    from tollcli.readers.gsdc import iter_gsdc_derived, read_gsdc_derived

    lines = (long_drive / "drive-derived.csv").read_text().splitlines(keepends=True)
    column = lines[0].strip().split(",").index("rawPrM")
    fields = lines[5_000].split(",")
    fields[column] = "2.1e7x"
    lines[5_000] = ",".join(fields)
    bad = tmp_path / "bad.csv"
    bad.write_text("".join(lines))
    for path in (str(shared("gsdc2021", "Pixel4_derived.csv")), str(bad)):
        whole = read_gsdc_derived(path)
        parts = list(iter_gsdc_derived(path, block_rows=1_997))
        pd.testing.assert_frame_equal(pd.concat(parts, ignore_index=True), whole)
        assert sum(p.attrs["skipped_lines"] for p in parts) == whole.attrs["skipped_lines"] == (path == str(bad))
    with pytest.raises(DataError, match=rf"{bad.name}:5001: rawPrM is not a number"):
        list(iter_gsdc_derived(str(bad), strict=True, block_rows=1_997))
    real = str(shared("gsdc2021", "Pixel4_derived.csv"))
    epochs, _, _ = with_trajectory(*pseudorange_epochs(real, "gsdc-derived", None, "nominal", 5.0, NominalModel()), "auto")
    with segments.placed_log(real, "gsdc-derived", None, "nominal", 5.0, NominalModel(), False, "auto") as placed:
        pd.testing.assert_frame_equal(pd.concat([p for p, _ in placed.chunks(700)], ignore_index=True), epochs)
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 600)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 600.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 150)
    with segments.placed_log(str(long_drive / "drive-derived.csv"), "gsdc-derived", None, "nominal", 5.0, NominalModel(), False,
                             "auto") as placed:  # fmt: skip
        parts = list(placed.chunks(700))
    assert placed.segments == 4 and placed.positioning == "smoothed"
    placed_epochs = pd.concat([p for p, _ in parts], ignore_index=True)
    assert (placed_epochs["epoch"].to_numpy() == np.arange(2_400)).all() and placed_epochs["gps_millis"].is_monotonic_increasing
    truth = pd.read_csv(long_drive / "truth.csv", parse_dates=["time_utc"]).set_index("time_utc").reindex(placed_epochs["time_utc"])
    zero = np.zeros(len(placed_epochs))
    e, n, _ = geodetic2enu(placed_epochs["lat_deg"].to_numpy(), placed_epochs["lon_deg"].to_numpy(), zero, truth["lat_deg"].to_numpy(),
                           truth["lon_deg"].to_numpy(), zero)  # fmt: skip
    hpl = np.concatenate([m.trajectory_hpl_m for _, m in parts])
    assert np.isfinite(np.hypot(e, n)).all() and (np.hypot(e, n) < hpl).all()


def test_a_full_disk_is_said_in_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    """Where the segments' temporary store has no room, `integrity` says so in one line naming the file and TMPDIR, exits
    with the system's code (4), and leaves neither a stored segment nor a table behind."""
    import subprocess
    import sys

    from conftest import REPO

    store = tmp_path / "store"
    store.mkdir()
    code = f"""
import errno, sys, numpy as np
import tollcli.job.pseudorange_segments as segments
segments.SEGMENT_EPOCHS, segments.SEGMENT_MIN_S, segments.MARGIN_EPOCHS = 300, 60.0, 50
save = np.save
def full(path, *args, **kwargs):
    if "tollcli-segments-" in str(path):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    return save(path, *args, **kwargs)
np.save = full
from tollcli.cli.main import main
main(["integrity", {str(shared(*BERLIN))!r}, "-q", "-o", {str(tmp_path / "table.csv")!r}])
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                          env={**os.environ, "TMPDIR": str(store)}, timeout=300)  # fmt: skip
    assert done.returncode == 4, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "No space left on device" in lines[0] and "TMPDIR" in lines[0] and str(store) in lines[0]
    assert "Traceback" not in done.stderr
    assert not list(store.iterdir()) and not (tmp_path / "table.csv").exists()


def test_a_long_ubx_log_is_read_in_two_passes_and_placed_in_segments(tmp_path, monkeypatch):
    """A u-blox receiver simulated on the day's real orbits, driving 300 s at 20 m/s, cut into cores of 100 epochs:
    its navigation data read in a first pass, its RXM-RAWX a block of frames at a time in a second. Snapshot: every
    epoch the whole log's (to 1e-6 m). Smoothed: every epoch once, in order, within its bound of the known track."""
    from test_raw_measurements import T0_GPS_S, _nav
    from ubx_synth import simulate_ubx

    from tollcli.gnss.satellite_states import rinex_ephemeris_table
    from tollcli.readers import ubx as ubx_reader

    lat, lon = 37.3958, -122.1029
    path = tmp_path / "drive.ubx"
    path.write_bytes(simulate_ubx(rinex_ephemeris_table(_nav()), T0_GPS_S, 300, lat, lon, -4.5, vel_enu_mps=(-12.0, 16.0, 0.0), seed=3))
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 100)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 100.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 40)
    blocks = []
    real_iter = ubx_reader.iter_rawx
    monkeypatch.setattr(ubx_reader, "iter_rawx", lambda p, strict=False, **kw: (blocks.append(len(b[0])) or b for b in real_iter(p, strict, 4_000, **kw)))
    _placed_in_three_segments(str(path), "ubx", None, lat, lon, p95_m=5.0)
    assert len(blocks) > 10  # read a block of frames at a time


def _placed_in_three_segments(path: str, kind: str, nav, lat: float, lon: float, p95_m: float, velocity_en_mps=(-12.0, 16.0)) -> None:
    """A simulated receiver's 300 s log (from ``lat``/``lon`` at ``velocity_en_mps``, east and north) placed in three segments
    (the caller sets their size): snapshot, every epoch the whole log's (the WLS of a batch of epochs is the same to
    1e-14° and 1e-8 m whichever epochs are in the batch); smoothed, every epoch once, in order, within its bound of
    the known track, the 95th percentile of the error below ``p95_m``."""
    whole_epochs, _ = pseudorange_epochs(path, kind, nav, "nominal", 5.0, NominalModel())

    def placed(positioning):
        with segments.placed_log(path, kind, nav, "nominal", 5.0, NominalModel(), False, positioning) as log:
            parts = list(log.chunks(70))
        return log, pd.concat([p for p, _ in parts], ignore_index=True), parts

    log, epochs, parts = placed("snapshot")
    assert log.segments == 3
    pd.testing.assert_frame_equal(epochs.drop(columns=["epoch"]), whole_epochs.drop(columns=["epoch"]), check_exact=False, rtol=1e-12, atol=1e-6)
    assert (epochs["epoch"].to_numpy() == np.arange(300)).all()
    log, epochs, parts = placed("auto")
    assert log.segments == 3 and (epochs["positioning"] == "smoothed").all()
    assert (epochs["time_utc"].to_numpy() == whole_epochs["time_utc"].to_numpy()).all()
    t = np.arange(300.0)
    e, n, _ = geodetic2enu(epochs["lat_deg"].to_numpy(), epochs["lon_deg"].to_numpy(), np.zeros(300), np.full(300, lat), np.full(300, lon),
                           np.zeros(300))  # fmt: skip
    hpe = np.hypot(e - velocity_en_mps[0] * t, n - velocity_en_mps[1] * t)
    hpl = np.concatenate([m.trajectory_hpl_m for _, m in parts])
    assert (hpe < hpl).all() and np.percentile(hpe, 95) < p95_m, (hpe.max(), hpl.min(), np.percentile(hpe, 95))


@pytest.fixture(scope="module")
def phone_drive(tmp_path_factory):
    """A phone simulated on the day's real orbits, driving 300 s at 20 m/s: its records as a GnssLogger file and as a
    ``device_gnss.csv`` (orbits from ``--nav``), the navigation file, and the start's latitude and longitude."""
    from android_synth import device_gnss_csv, gnsslogger_text, raw_records
    from test_raw_measurements import T0_GPS_S, _nav

    from tollcli.gnss.satellite_states import rinex_ephemeris_table

    lat, lon = 37.3958, -122.1029
    records = raw_records(rinex_ephemeris_table(_nav()), T0_GPS_S, 300, lat, lon, -4.5, vel_enu_mps=(-12.0, 16.0, 0.0), seed=3)
    folder = tmp_path_factory.mktemp("phone")
    (folder / "drive.txt").write_text(gnsslogger_text(records, lat, lon))
    (folder / "device_gnss.csv").write_text(device_gnss_csv(records))
    return folder, str(shared("rinex", "brdc1190.21n")), lat, lon


def test_android_logs_read_in_blocks_are_the_whole_files_records(phone_drive, tmp_path):
    """GnssLogger files and device_gnss.csv read a block at a time are the whole file's records, line numbers and
    skipped lines: the real ones, and the simulated phone's with a Raw line cut short and a number that is none. With
    --strict the error names the damaged line itself (it named the record's place among the Raw records before)."""
    from tollcli.readers.gnsslogger import iter_device_gnss, iter_gnsslogger, read_device_gnss, read_gnsslogger

    folder = phone_drive[0]
    lines = (folder / "drive.txt").read_text().splitlines(keepends=True)
    cut, wrong = 1_200, 2_000
    lines[cut] = lines[cut].rsplit(",", 2)[0] + "\n"
    lines[wrong] = lines[wrong].replace(",42.0,", ",4x.0,", 1)
    bad = tmp_path / "bad.txt"
    bad.write_text("".join(lines).replace("\n", "\r\n"))  # CR LF line ends as well
    for path in (shared("android", "pixel6_gnsslogger.txt"), shared("gsdc2021", "Pixel4_GnssLog.txt"), folder / "drive.txt", bad):
        whole = read_gnsslogger(str(path))
        parts = list(iter_gnsslogger(str(path), block_bytes=4_001))
        assert len(parts) > 2
        pd.testing.assert_frame_equal(pd.concat([p.raw for p in parts if p.raw is not None], ignore_index=True), whole.raw)
        assert sum(p.n_malformed for p in parts) == whole.n_malformed == 2 * (path == bad)
    assert read_gnsslogger(str(bad)).first_malformed_line == cut + 1
    assert read_gnsslogger(str(bad)).raw["line"].iloc[-1] == len(lines)
    with pytest.raises(DataError, match=rf"{bad.name}:{cut + 1}: a Raw record with"):
        read_gnsslogger(str(bad), strict=True)
    lines[cut] = lines[cut - 1]
    bad.write_text("".join(lines))
    with pytest.raises(DataError, match=rf"{bad.name}:{wrong + 1}: Cn0DbHz is not a number"):
        list(iter_gnsslogger(str(bad), strict=True, block_bytes=4_001))
    for path in (shared("gsdc2022", "device_gnss.csv"), folder / "device_gnss.csv"):
        whole = read_device_gnss(str(path))
        parts = list(iter_device_gnss(str(path), block_rows=97))
        pd.testing.assert_frame_equal(pd.concat(parts, ignore_index=True), whole)


@pytest.mark.parametrize("kind", ["gnsslogger", "device-gnss"])
def test_a_long_android_log_is_placed_in_segments(phone_drive, monkeypatch, kind):
    """The simulated phone's log (with --nav) cut into cores of 100 epochs. Snapshot: every epoch the whole log's (to
    1e-6 m). Smoothed: every epoch once, in order, within its bound of the known track. With the default segment (the
    log is one): placed exactly as when read whole; the real device_gnss.csv too."""
    folder, nav, lat, lon = phone_drive
    path = str(folder / ("drive.txt" if kind == "gnsslogger" else "device_gnss.csv"))
    for log, log_nav in ((path, nav), (str(shared("gsdc2022", "device_gnss.csv")), None)):
        if log_nav is None and kind == "gnsslogger":
            continue
        epochs, meas, _ = with_trajectory(*pseudorange_epochs(log, kind, log_nav, "nominal", 5.0, NominalModel()), "auto")
        with segments.placed_log(log, kind, log_nav, "nominal", 5.0, NominalModel(), False, "auto") as placed:
            (one, one_meas), = placed.chunks(10_000)
        assert placed.segments == 1
        pd.testing.assert_frame_equal(one, epochs)
        _same_measurements(one_meas, meas)
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 100)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 100.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 40)
    _placed_in_three_segments(path, kind, nav, lat, lon, p95_m=10.0)


def test_a_long_rinex_file_is_read_in_two_passes_and_placed_in_segments(tmp_path, monkeypatch):
    """A receiver simulated for 300 s (RINEX 3.04 observations and navigation), cut into cores of 100 epochs: the rows
    read a block of epochs at a time are the whole file's; snapshot positions the whole log's, smoothed each within its
    bound; the same file of one segment placed to the bit as before. The same observations in RINEX 2.11: the same,
    read by the RINEX 2 reader (they were read whole by georinex before); a copy the direct readers leave to georinex
    (an epoch flagged 6) is read and placed whole; without --nav the error is the same."""
    from rinex_synth import make_rinex

    from tollcli.errors import UsageError
    from tollcli.readers.rinex3_obs import rinex3_plan
    from tollcli.readers.rinex_obs import iter_observation_rows, observation_plan, observation_rows

    obs, nav, _rows = make_rinex(tmp_path, n_epochs=300, noise_m=1.0, seed=4)
    obs, nav = str(obs), str(nav)
    (tmp_path / "v2").mkdir()
    version2 = str(make_rinex(tmp_path / "v2", n_epochs=300, noise_m=1.0, seed=4, version=2)[0])
    assert rinex3_plan(version2) is None and observation_plan(version2).version == 2
    for path in (obs, version2):
        parts = list(iter_observation_rows(path, observation_plan(path), 37))
        assert len(parts) == 9
        pd.testing.assert_frame_equal(pd.concat(parts, ignore_index=True), observation_rows(path))
        epochs, meas, _ = with_trajectory(*pseudorange_epochs(path, "rinex", nav, "nominal", 5.0, NominalModel()), "auto")
        with segments.placed_log(path, "rinex", nav, "nominal", 5.0, NominalModel(), False, "auto") as placed:
            (one, one_meas), = placed.chunks(10_000)
        assert placed.segments == 1 and (one["positioning"] == "smoothed").all()
        pd.testing.assert_frame_equal(one, epochs)
        _same_measurements(one_meas, meas)
        with pytest.raises(UsageError, match="give --nav"):
            segments.placed_log(path, "rinex", None, "nominal", 5.0, NominalModel(), False, "auto")
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 100)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 100.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 40)
    for path in (obs, version2):
        _placed_in_three_segments(path, "rinex", nav, 42.6987, 2.8956, p95_m=5.0, velocity_en_mps=(0.0, 0.0))
    lines = open(version2).read().splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    flagged = tmp_path / "v2" / "flagged.24o"
    flagged.write_text("".join(lines[:at] + [lines[at][:28] + "6" + lines[at][29:]] + lines[at + 1 :]))
    assert observation_plan(str(flagged)) is None
    epochs, _, _ = with_trajectory(*pseudorange_epochs(str(flagged), "rinex", nav, "nominal", 5.0, NominalModel()), "auto")
    with segments.placed_log(str(flagged), "rinex", nav, "nominal", 5.0, NominalModel(), False, "auto") as placed:
        assert placed.segments == 1
        pd.testing.assert_frame_equal(pd.concat([p for p, _ in placed.chunks(70)], ignore_index=True), epochs)


def _shifted_after(obs, out, after: tuple[int, int, int], hours: float) -> str:
    """A copy of a RINEX 3 observation file whose epochs from ``after`` (hour, minute, second of its day) on are
    ``hours`` later: beyond its navigation file's orbits (4 h)."""
    import datetime as dt

    lines = []
    for line in open(obs).read().splitlines(keepends=True):
        if line.startswith("> "):
            t = dt.datetime(int(line[2:6]), int(line[7:9]), int(line[10:12]), int(line[13:15]), int(line[16:18]), int(line[19:21]))
            if (t.hour, t.minute, t.second) >= after:
                t += dt.timedelta(hours=hours)
                line = f"> {t:%Y %m %d %H %M}{t.second:11.7f}" + line[29:]
        lines.append(line)
    open(out, "w").write("".join(lines))
    return str(out)


def test_a_segment_without_orbits_is_placed_without_positions(tmp_path, monkeypatch):
    """The simulated receiver's RINEX log whose last 150 epochs come 5 h later, beyond its navigation file: read whole
    they are epochs without a measurement to solve; cut into segments, the segment of those epochs alone is placed
    without positions (it stopped the whole log with "no observation has a satellite orbit" before), the note says
    which epochs and why, and the others are placed as before. A log none of whose segments has an orbit is the error
    it is read whole."""
    from rinex_synth import make_rinex

    obs, nav, _rows = make_rinex(tmp_path, n_epochs=300, noise_m=1.0, seed=4)
    gap = _shifted_after(obs, tmp_path / "gap.24o", (8, 2, 30), 5.0)
    whole, _ = pseudorange_epochs(gap, "rinex", str(nav), "nominal", 5.0, NominalModel())
    assert whole["lat_deg"].notna().sum() == 150
    monkeypatch.setattr(segments, "SEGMENT_EPOCHS", 100)
    monkeypatch.setattr(segments, "SEGMENT_MIN_S", 100.0)
    monkeypatch.setattr(segments, "MARGIN_EPOCHS", 40)
    for positioning in ("snapshot", "auto"):
        with segments.placed_log(gap, "rinex", str(nav), "nominal", 5.0, NominalModel(), False, positioning) as placed:
            epochs = pd.concat([p for p, _ in placed.chunks(70)], ignore_index=True)
        assert placed.segments == 3 and len(epochs) == 300 and epochs["lat_deg"].iloc[200:].isna().all()
        assert placed.note.startswith("epochs 200–299: no observation has a satellite orbit in") and gap not in placed.note
        if positioning == "snapshot":
            pd.testing.assert_frame_equal(epochs.drop(columns=["epoch"]), whole.drop(columns=["epoch"]), check_exact=False, rtol=1e-12,
                                          atol=1e-6)  # fmt: skip
        else:
            assert epochs["lat_deg"].iloc[:150].notna().all() and placed.positioning == "smoothed"
    late = _shifted_after(obs, tmp_path / "late.24o", (0, 0, 0), 5.0)
    with pytest.raises(DataError, match="no observation has a satellite orbit"):
        pseudorange_epochs(late, "rinex", str(nav), "nominal", 5.0, NominalModel())
    with pytest.raises(DataError, match="no observation has a satellite orbit"):
        segments.placed_log(late, "rinex", str(nav), "nominal", 5.0, NominalModel(), False, "auto")


def test_measurements_without_orbits_give_the_columns_of_a_solved_segment(phone_drive):
    """The simulated phone's measurements with no satellite orbit: an error where the orbits are required (a log read
    whole), else its epochs without positions, in the columns a solved segment has (the segments are stored and read
    back as one table), and measurements of no satellite."""
    from tollcli.gnss.android_raw import raw_pseudoranges
    from tollcli.gnss.pseudorange_inputs import navigation_of
    from tollcli.gnss.raw_positions import SAT_COLUMNS, raw_epochs, with_broadcast_satellites
    from tollcli.gnss.satellite_states import NoOrbitForRows
    from tollcli.readers.gnsslogger import read_device_gnss

    device = read_device_gnss(str(phone_drive[0] / "device_gnss.csv"))
    rows = with_broadcast_satellites(raw_pseudoranges(device), navigation_of(phone_drive[1])[0])
    solved, _ = raw_epochs(rows)
    bare = rows.assign(**{c: np.nan for c in SAT_COLUMNS})
    with pytest.raises(NoOrbitForRows):
        raw_epochs(bare)
    epochs, meas = raw_epochs(bare, orbits_required=False)
    assert list(epochs.columns) == list(solved.columns) and len(epochs) == len(solved) and epochs["lat_deg"].isna().all()
    assert meas.mask.shape == (len(epochs), 0)


def test_a_sigma_model_rinex_cannot_give_is_refused_before_the_log_is_read(tmp_path, monkeypatch):
    """``--sigma-model input`` of a RINEX log: refused before its first pass (which reads the whole file)."""
    from rinex_synth import make_rinex

    from tollcli.errors import UsageError
    from tollcli.readers import rinex_obs

    obs, nav, _rows = make_rinex(tmp_path, n_epochs=5)
    monkeypatch.setattr(rinex_obs, "observation_plan", lambda *a, **k: pytest.fail("the log was read"))
    with pytest.raises(UsageError, match="--sigma-model input: RINEX observations carry no per-measurement σ"):
        segments.placed_log(str(obs), "rinex", str(nav), "input", 5.0, NominalModel(), False, "auto")
