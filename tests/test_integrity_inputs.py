"""RAIM inputs from real and constructed logs: NMEA (GRS, GST, none) and the GSDC derived CSV."""

from __future__ import annotations

import datetime as dt
import io

import numpy as np
import pandas as pd
import pytest
from conftest import shared

from tollcli.geodesy import enu_rotation, geodetic2ecef
from tollcli.gnss.gsdc_positions import gsdc_epochs
from tollcli.gnss.nmea_measurements import AngleCarry, nmea_measurements
from tollcli.gnss.sigma_models import NominalModel
from tollcli.integrity.raim import RaimParams
from tollcli.integrity.run import run_raim
from tollcli.readers.gps_time import gps_millis_to_utc
from tollcli.readers.gsdc import read_gsdc_derived
from tollcli.readers.nmea import compose, read_nmea


def _tables(lines):
    return read_nmea(io.BytesIO(("\n".join(lines) + "\n").encode()))


def _epoch_with_grs(tod, residuals, with_gsv=True):
    sats = [(3, 62.0, 45.0, 44.0), (7, 35.0, 130.0, 41.0), (9, 48.0, 250.0, 42.0), (16, 21.0, 310.0, 37.0),
            (22, 15.0, 200.0, 35.0), (27, 70.0, 90.0, 45.0)]  # fmt: skip
    lines = [compose.rmc(tod, 42.7, 2.9, 10.0, 45.0, dt.date(2024, 5, 6)), compose.gga(tod, 42.7, 2.9, n_used=6),
             compose.gsa([p for p, *_ in sats], 1.5, 0.9, 1.2, talker="GP")]  # fmt: skip
    if with_gsv:
        lines += compose.gsv(sats)
    lines.append(compose.grs(tod, residuals, talker="GP"))
    return lines


def test_grs_residuals_give_the_exact_statistic():
    residuals = [1.0, -2.0, 0.5, 3.0, -1.5, 0.25]
    tables = _tables(_epoch_with_grs(100.0, residuals))
    meas = nmea_measurements(tables.epochs, tables.satellites, sigma_model="constant", sigma_m=2.0)
    out = run_raim(meas, RaimParams("etc"))
    assert out["test_stat_source"].iloc[0] == "grs"
    # the receiver's residuals are of its own solution: the RAIM's weighted solution moves by A·r and its residuals
    # are (I − H·A)·r; the statistic is theirs (residuals that already are the RAIM's own give Σ r²/σ² exactly)
    H = meas.H[0][meas.mask[0]]
    A = np.linalg.solve(H.T @ H, H.T)  # equal σ: the weights cancel
    r = np.asarray(residuals)
    own = r - H @ (A @ r)
    assert out["test_stat"].iloc[0] == pytest.approx(float(own @ own) / 4.0)
    assert out["n_used"].iloc[0] == 6 and out["dof"].iloc[0] == 2
    again = _tables(_epoch_with_grs(100.0, [round(float(v), 2) for v in own]))
    out = run_raim(nmea_measurements(again.epochs, again.satellites, sigma_model="constant", sigma_m=2.0), RaimParams("etc"))
    assert out["test_stat"].iloc[0] == pytest.approx(float(own @ own) / 4.0, abs=0.005)  # GRS writes 0.01 m
    assert abs(out["wls_shift_e_m"].iloc[0]) < 0.02 and abs(out["wls_shift_n_m"].iloc[0]) < 0.02


def test_gsv_angles_carry_forward_within_their_age_and_across_chunks():
    lines = _epoch_with_grs(100.0, [0.1] * 6) + _epoch_with_grs(101.0, [0.1] * 6, with_gsv=False)
    lines += _epoch_with_grs(200.0, [0.1] * 6, with_gsv=False)  # 99 s later: too old to reuse
    tables = _tables(lines)
    out = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc"))
    assert out["n_used"].tolist() == [6, 6, 0]
    assert out["raim_status"].tolist()[2] == "insufficient"
    # the same when the second epoch arrives in a later chunk
    carry = AngleCarry()
    first, second = tables.epochs.iloc[:1], tables.epochs.iloc[1:2]
    s = tables.satellites
    nmea_measurements(first, s[s.epoch == 0], carry=carry)
    later = nmea_measurements(second, s[s.epoch == 1], carry=carry)
    assert later.mask.sum() == 6


def test_gst_only_is_a_flagged_approximation_and_nothing_is_unmonitored():
    tables = _tables(list(compose.straight_drive(3)))  # GST, no GRS
    out = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc"))
    assert (out["test_stat_source"] == "gst").all() and (out["integrity_source"] == "gst").all()
    bare = _tables([line for line in compose.straight_drive(3) if "GST" not in line])
    out = run_raim(nmea_measurements(bare.epochs, bare.satellites), RaimParams("etc"))
    # GSA + GSV only: the model level (geometry, no environment measured: the urban σ) bounds nothing within 50 m
    assert (out["raim_status"] == "unavailable").all() and (out["integrity_source"] == "model").all()
    assert (out["hpl_model_m"] > 50).all() and out["hpl_m"].notna().all() and out["threshold"].notna().all()
    classic = run_raim(nmea_measurements(bare.epochs, bare.satellites), RaimParams("classic"))
    assert classic["slope_max_m"].notna().all() and (classic["raim_status"] != "valid").all()


def test_android_log_without_satellites_cannot_be_monitored():
    """GGA + RMC only: no residual test; the model level's HDOP bound (HDOP · σ_worst, urban σ) is no charge."""
    tables = read_nmea(shared("android", "pixel6.nmea"))
    out = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc"))
    assert len(out) == 48 and (out["test_stat_source"] == "none").all()
    assert (out["raim_status"] == "unavailable").all() and (out["integrity_source"] == "model").all()
    no_hdop = tables.epochs.assign(hdop=np.nan)
    out = run_raim(nmea_measurements(no_hdop, tables.satellites), RaimParams("etc"))
    assert (out["raim_status"] == "unmonitored").all()


def test_every_gpsd_log_gets_a_status_per_epoch():
    folder = shared("gpsd")
    for log in sorted(folder.glob("*.log")):
        tables = read_nmea(log)
        out = run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc", fde=True))
        assert len(out) == len(tables.epochs)
        assert out["raim_status"].notna().all()


def test_gps_time_to_utc():
    # GSDC 2020-05-14: GPS − UTC = 18 s
    assert str(gps_millis_to_utc(np.array([1273529464442]))[0]) == "2020-05-14T22:10:46.442"


def test_gsdc_wls_positions_against_ground_truth():
    derived = read_gsdc_derived(shared("gsdc2021", "Pixel4_derived.csv"))
    truth = pd.read_csv(shared("gsdc2021", "Pixel4_ground_truth.csv")).set_index("millisSinceGpsEpoch")
    for model in ("input", "nominal"):
        epochs, meas = gsdc_epochs(derived, sigma_model=model, nominal=NominalModel())
        assert len(epochs) == 7
        gt = truth.loc[epochs["gps_millis"]]
        ours = np.array(geodetic2ecef(epochs.lat_deg.to_numpy(), epochs.lon_deg.to_numpy(), epochs.height_m.to_numpy())).T
        ref = np.array(geodetic2ecef(gt.latDeg.to_numpy(), gt.lngDeg.to_numpy(), gt.heightAboveWgs84EllipsoidM.to_numpy())).T
        enu = np.einsum("eij,ej->ei", enu_rotation(gt.latDeg.to_numpy(), gt.lngDeg.to_numpy()), ours - ref)
        horizontal = np.hypot(enu[:, 0], enu[:, 1])
        # a Pixel 4 single-frequency WLS: metres. (The truth file's heights sit ~65 m above every WLS solution,
        # gnss_lib_py's included, so only the horizontal error is asserted.)
        assert horizontal.max() < 5.0, horizontal
        out = run_raim(meas, RaimParams("etc", fde=True))
        assert out["raim_status"].notna().all() and (out["test_stat_source"] == "pseudorange").all()
        assert (out["n_used"] >= 27).all()


def test_gsdc_bad_rows_do_not_raise(tmp_path):
    derived = read_gsdc_derived(shared("gsdc2021", "Pixel4_derived.csv"))
    bad = derived.copy()
    millis = np.sort(bad["millisSinceGpsEpoch"].unique())
    in_epoch = bad.groupby("millisSinceGpsEpoch").cumcount()
    bad.loc[(bad["millisSinceGpsEpoch"] == millis[0]) & (in_epoch >= 3), "rawPrM"] = np.nan  # 3 left for 4 unknowns
    bad.loc[bad["millisSinceGpsEpoch"] == millis[1], "xSatPosM"] = np.nan  # nothing usable left
    bad = pd.concat([bad, bad.iloc[-3:]])  # duplicated rows count once
    epochs, meas = gsdc_epochs(bad, sigma_model="input")
    out = run_raim(meas, RaimParams("etc", fde=True))
    assert len(epochs) == 7  # every epoch keeps its row
    assert out["raim_status"].iloc[0] == out["raim_status"].iloc[1] == "insufficient"
    assert out["n_used"].tolist()[:2] == [3, 0]
    assert epochs["lat_deg"].iloc[:2].isna().all()
    assert (out["raim_status"].iloc[2:] == "valid").all()


def test_a_gga_only_log_is_model_level_and_a_gsa_with_too_few_satellites_insufficient(tmp_path):
    """No satellites reported at all: the HDOP bound only (no charge under the urban σ). Satellites in view (GSV)
    but none said to be used (no GSA): no geometry of the fix either, so the same HDOP bound, to the bit
    (metamorphic). Three used satellites with their angles: a geometry too small to check, insufficient."""
    from conftest import SAMPLES

    from tollcli.readers.nmea.compose import gsa

    def raim(name, keep, edit=lambda line: line):
        path = tmp_path / name
        path.write_text("\n".join(e for e in (edit(line) for line in lines if line[3:6] in keep) if e) + "\n")
        tables = read_nmea(path)
        return run_raim(nmea_measurements(tables.epochs, tables.satellites), RaimParams("etc"))

    lines = (SAMPLES / "straight-drive.nmea").read_text().splitlines()
    gga_only = raim("gga.nmea", ("GGA", "RMC"))
    assert len(gga_only) == 180 and (gga_only["raim_status"] == "unavailable").all()
    assert (gga_only["integrity_source"] == "model").all()
    in_view = raim("gsv.nmea", ("GGA", "RMC", "GSV"))
    assert in_view["raim_status"].tolist() == gga_only["raim_status"].tolist()
    np.testing.assert_array_equal(in_view["hpl_model_m"].to_numpy(float), gga_only["hpl_model_m"].to_numpy(float))

    def three_used(line):  # the GPS GSA names three of its satellites; the Galileo GSA is left out
        if line.startswith("$GNGSA"):
            return gsa([3, 7, 9], 9.9, 9.9, 9.9, system_id=1) if line.endswith(",1*01") else None
        return line

    three = raim("three.nmea", ("GGA", "RMC", "GSV", "GSA"), three_used)
    assert (three["n_used"] == 3).all() and (three["raim_status"] == "insufficient").all()


@pytest.mark.parametrize("dtype", ["string[pyarrow]", object])
@pytest.mark.parametrize("with_missing", [False, True])
def test_constellation_codes_name_the_rows_as_factorizing_their_names_does(dtype, with_missing):
    """The constellation of each used row, coded from the whole column (the reader's Arrow strings coded at once),
    names the same constellation in the same (name) order as ``pandas.factorize`` of just those rows' names."""
    from tollcli.gnss.nmea_measurements import _compact, _constellation_codes

    rng = np.random.default_rng(5)
    names = np.array(["GPS", "Galileo", "BeiDou", "GLONASS", "QZSS"], dtype=object)
    values = names[rng.integers(0, 5, 400)]
    if with_missing:
        values[rng.integers(0, 400, 20)] = None
    column = pd.Series(values, dtype=dtype)
    rows = np.sort(rng.choice(400, 150, replace=False))
    codes, got = _compact(*_constellation_codes(column, rows))
    want_codes, want = _compact(*pd.factorize(column.to_numpy(dtype=object)[rows], sort=True, use_na_sentinel=False))
    np.testing.assert_array_equal(codes, want_codes)
    assert [None if pd.isna(n) else n for n in got] == [None if pd.isna(n) else n for n in want]


def test_angle_lookup_takes_epochs_in_any_order():
    from tollcli.gnss.nmea_measurements import _lookup

    keys, values = np.array([3, 1, 7, 5]), np.array([30.0, 10.0, 70.0, 50.0])
    np.testing.assert_array_equal(_lookup(keys, values, np.array([5, 2, 3, 7, 9, 1])), [50.0, np.nan, 30.0, 70.0, np.nan, 10.0])
    np.testing.assert_array_equal(_lookup(np.sort(keys), np.sort(values), np.array([5, 2, 3])), [50.0, np.nan, 30.0])


@pytest.mark.parametrize("seed", range(6))
def test_angle_lookup_of_consecutive_epochs_is_the_searched_one(seed):
    """A chunk's epoch numbers are consecutive: looked up by their distance from the first, every wanted number
    (repeated, out of range below and above, shuffled keys) gets what the sorted search gives."""
    from tollcli.gnss.nmea_measurements import _lookup

    rng = np.random.default_rng(seed)
    first, n = int(rng.integers(0, 10**6)), int(rng.integers(1, 400))
    keys = np.arange(first, first + n)
    values = rng.normal(size=n)
    if seed % 2:
        order = rng.permutation(n)
        keys, values = keys[order], values[order]
    wanted = rng.integers(first - 20, first + n + 20, 2000)
    gaps = np.delete(keys, rng.integers(0, n, min(n - 1, 3))) if n > 4 else keys  # not consecutive: the search
    expected = np.array([values[keys == w][0] if (keys == w).any() else np.nan for w in wanted])
    np.testing.assert_array_equal(_lookup(keys, values, wanted), expected)
    kept = np.isin(keys, gaps)
    expected = np.array([values[kept][gaps == w][0] if (gaps == w).any() else np.nan for w in wanted])
    np.testing.assert_array_equal(_lookup(gaps, values[kept], wanted), expected)


def _same_fields(a, b, where: str) -> None:
    """Every field of two dataclass instances (Measurements, ReceiverOutputs) equal, arrays element by element."""
    import dataclasses

    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if dataclasses.is_dataclass(x):
            _same_fields(x, y, f"{where}.{field.name}")
        elif isinstance(x, np.ndarray):
            assert isinstance(y, np.ndarray) and x.dtype == y.dtype, f"{where}.{field.name}"
            np.testing.assert_array_equal(x, y, err_msg=f"{where}.{field.name}")
        else:
            assert x == y, f"{where}.{field.name}"


def test_the_readers_columns_give_the_measurements_and_cn0_summary_of_its_frame():
    """``process`` hands the NMEA reader's satellite columns to the measurements and the C/N0 summary without building
    a DataFrame: over every gpsd NMEA log, read in small chunks (the angles carried from chunk to chunk), every array
    of the measurements and every C/N0 summary equals the one made from the frame. Logs whose used satellites lack
    angles (filled from earlier GSV) take the frame's path inside; both kinds are among the logs."""
    from tollcli.enforcement.trip import cn0_summary
    from tollcli.gnss.nmea_measurements import fill_angles
    from tollcli.io.columns import Columns
    from tollcli.readers.nmea.reader import iter_nmea_tables

    folder = shared("gpsd")
    filled = plain = 0
    for log in sorted(folder.glob("*.log")):
        carry_columns, carry_frame = AngleCarry(), AngleCarry()
        for k, chunk in enumerate(iter_nmea_tables(str(log), chunk_epochs=25, block_bytes=4096)):
            columns = chunk.satellites_read
            assert isinstance(columns, Columns)
            frame = columns.to_pandas()
            epochs = chunk.epochs
            if len(frame):
                probe = fill_angles(frame, epochs)
                filled, plain = filled + (probe is not frame), plain + (probe is frame)
            got = nmea_measurements(epochs, columns, carry=carry_columns)
            want = nmea_measurements(epochs, frame, carry=carry_frame)
            _same_fields(got, want, f"{log.name} chunk {k}")
            pd.testing.assert_frame_equal(carry_columns.last, carry_frame.last)
            if len(epochs):
                first = int(epochs["epoch"].iat[0])
                pd.testing.assert_frame_equal(cn0_summary(columns, len(epochs), first), cn0_summary(frame, len(epochs), first))
    assert filled > 0 and plain > 0


@pytest.mark.parametrize("seed", range(6))
def test_sorted_codes_are_factorizing_the_names_in_order(seed):
    """A coded column's codes in its names' sorted order name the rows as ``pandas.factorize(sort=True)`` does, once
    the names no row has are dropped."""
    from tollcli.gnss.nmea_measurements import _compact
    from tollcli.io.columns import Coded, sorted_codes

    rng = np.random.default_rng(seed)
    names = tuple(rng.permutation(["GPS", "Galileo", "BeiDou", "GLONASS", "QZSS", "NavIC", "SBAS", "unknown"]))
    codes = rng.integers(0, rng.integers(1, 9), 300)
    column = Coded(codes, names)
    got = _compact(*sorted_codes(column))
    want = pd.factorize(column.decoded(), sort=True)
    np.testing.assert_array_equal(got[0], want[0])
    assert list(got[1]) == list(want[1])


def test_integrity_chunks_still_give_the_readers_satellite_frame():
    """``iter_integrity`` measures from the reader's satellite columns; a consumer that asks for a chunk's satellite
    table (``findings``, ``locate``) still gets the reader's DataFrame, row for row."""
    from tollcli.job.log_integrity import iter_integrity

    folder = shared("gpsd")
    logs = [log for log in sorted(folder.glob("*.log")) if len(read_nmea(log).satellites)][:12]
    assert logs
    for log in logs:
        chunks = list(iter_integrity(str(log), "nmea", RaimParams("ss")))
        got = pd.concat([c.satellites for c in chunks], ignore_index=True)
        pd.testing.assert_frame_equal(got, read_nmea(log).satellites.reset_index(drop=True))
