"""RTKLIB solution files (.pos): read in every time and position layout, their σ as the receiver's error ellipse.

The real files come from Debian's ``rnx2rtkp`` (CI installs ``rtklib`` as it installs chromium; the tests skip
without it) run on a real phone's GPS L1 pseudoranges (``../shared/data/gsdc2022/device_gnss.csv`` written as
RINEX, with that day's ``brdc1190.21n``), and checked against the GSDC truth of those epochs.
"""

from __future__ import annotations

import io
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import run_cli
from rinex_from_raw import write_rinex_obs
from tollcli.readers.rtklib_pos import ellipse, iter_rtklib_pos_tables

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared" / "data"

HEADER = """% program   : RTKLIB ver.2.4.3 b34
% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)
%  GPST          latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio
"""


def _read(text: str, **kwargs) -> pd.DataFrame:
    return pd.concat([t.epochs for t in iter_rtklib_pos_tables(io.BytesIO(text.encode()), **kwargs)], ignore_index=True)


def test_ellipse_of_rtklib_sigmas():
    assert ellipse(3.0, 4.0, 0.0) == pytest.approx((4.0, 3.0, 90.0))  # east the larger: the major axis points east
    major, minor, orient = ellipse(2.0, 2.0, math.sqrt(2.0))  # c = +2: σ² 4 ± 2 along NE and NW
    assert (major, minor, orient) == pytest.approx((math.sqrt(6), math.sqrt(2), 45.0))
    assert ellipse(2.0, 2.0, -math.sqrt(2.0))[2] == pytest.approx(135.0)  # the sign is the covariance's


def test_a_solution_line_becomes_an_epoch():
    e = _read(HEADER + "2021/04/29 22:35:44.000   37.395796054 -122.102946680    19.8570   5   6   5.2439   6.9484  11.6582  -3.3942   4.2770  -5.6349   0.00    0.0\n"
                       "2021/04/29 22:35:45.000   37.395806818 -122.102967205    21.8401   2  11   0.0439   0.0484   0.0582   0.0000   0.0   0.0   1.00    2.1\n")  # fmt: skip
    assert str(e["time_utc"].iloc[0]) == "2021-04-29 22:35:26+00:00"  # GPST − 18 s
    assert e["lat_deg"].iloc[0] == 37.395796054 and e["fix_quality"].tolist() == [1, 5] and e["n_used"].tolist() == [6, 11]
    assert e["mode_indicator"].tolist() == ["A", "F"]
    assert (e["sigma_lat_m"].iloc[0], e["sigma_lon_m"].iloc[0], e["sigma_alt_m"].iloc[0]) == (5.2439, 6.9484, 11.6582)
    assert e["sigma_major_m"].iloc[0] == pytest.approx(ellipse(5.2439, 6.9484, -3.3942)[0])


def test_bad_lines_are_counted_and_strict_refuses_them():
    from tollcli.errors import DataError
    from tollcli.readers.nmea import ReadStats

    text = HEADER + "2021/04/29 22:35:44.000   37.39 -122.10  19.8  5  6  5.2  6.9  11.6  -3.3  4.2  -5.6  0.00  0.0\nnot a solution\n"
    stats = ReadStats()
    assert len(_read(text, stats=stats)) == 1 and stats.malformed == 1 and ":5:" in stats.first_problem
    with pytest.raises(DataError, match=":5: not an RTKLIB solution line"):
        _read(text, strict=True)
    with pytest.raises(DataError, match="without one solution"):
        _read(HEADER)


def test_an_rtklib_file_is_recognised_and_checked(tmp_path):
    pos = tmp_path / "drive.pos"
    pos.write_text(HEADER + "2021/04/29 22:35:44.000   37.395796054 -122.102946680    19.8570   5   6   5.2439   6.9484  11.6582  -3.3942   4.2770  -5.6349   0.00    0.0\n")
    out = tmp_path / "i.csv"
    proc = run_cli("integrity", str(pos), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out)
    assert table["integrity_source"].tolist() == ["gst"] and table["raim_status"].tolist() == ["valid"]
    assert b"RTKLIB solutions" in proc.stderr


# ---------------------------------------------------------------- Debian's rnx2rtkp on real measurements
def _need_rtklib(*paths: Path) -> None:
    """Skip (saying why) without Debian's rnx2rtkp or the shared data."""
    if shutil.which("rnx2rtkp") is None:
        pytest.skip("Debian's rnx2rtkp (apt-get install rtklib) is not installed")
    if not all(p.exists() for p in paths):
        pytest.skip("shared data not present")


@pytest.fixture(scope="module")
def rtklib_runs(tmp_path_factory):
    raw, nav = SHARED / "gsdc2022" / "device_gnss.csv", SHARED / "rinex" / "brdc1190.21n"
    _need_rtklib(raw, nav)
    folder = tmp_path_factory.mktemp("rtklib")
    obs = folder / "phone.21o"
    assert write_rinex_obs(str(raw), str(obs)) == 6
    runs = {}
    for name, flags in {"week": [], "date_utc": ["-t", "-u"], "ecef": ["-e"], "dms": ["-t", "-g"]}.items():
        out = folder / f"{name}.pos"
        subprocess.run(["rnx2rtkp", "-p", "0", *flags, "-o", str(out), str(obs), str(nav)], capture_output=True, check=True, timeout=120)
        runs[name] = out
    return runs


def test_rnx2rtkp_solutions_are_read_in_every_layout(rtklib_runs):
    tables = {name: pd.concat([t.epochs for t in iter_rtklib_pos_tables(str(path))]) for name, path in rtklib_runs.items()}
    week = tables["week"]
    assert len(week) == 6 and (week["fix_quality"] == 1).all() and (week["n_used"] >= 5).all()
    for name, table in tables.items():
        assert table["time_utc"].tolist() == week["time_utc"].tolist(), name
        assert np.allclose(table["lat_deg"], week["lat_deg"], atol=2e-7) and np.allclose(table["lon_deg"], week["lon_deg"], atol=2e-7), name
    assert np.isfinite(week["sigma_major_m"]).all() and np.isnan(tables["ecef"]["sigma_major_m"]).all()  # sdx/sdy/sdz: no ellipse


def test_rtklib_bound_holds_against_the_truth(rtklib_runs, tmp_path):
    """RTKLIB's own σ (read as the covariance level) bounds the phone's real error on every epoch."""
    out = tmp_path / "i.csv"
    proc = run_cli("integrity", str(rtklib_runs["date_utc"]), "-o", str(out), "-q")
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out, parse_dates=["time_utc"])
    truth = pd.read_csv(SHARED / "gsdc2022" / "ground_truth.csv")
    t_truth = pd.to_datetime(truth["UnixTimeMillis"], unit="ms", utc=True)
    nearest = [int(np.argmin(np.abs((t_truth - t).dt.total_seconds()))) for t in table["time_utc"]]
    assert all(abs((t_truth[i] - t).total_seconds()) < 0.5 for i, t in zip(nearest, table["time_utc"]))
    lat0 = math.radians(truth["LatitudeDegrees"].iloc[0])
    dn = (table["lat_deg"].to_numpy() - truth["LatitudeDegrees"].to_numpy()[nearest]) * 111_132.0
    de = (table["lon_deg"].to_numpy() - truth["LongitudeDegrees"].to_numpy()[nearest]) * 111_320.0 * math.cos(lat0)
    hpe = np.hypot(dn, de)
    assert (table["integrity_source"] == "gst").all() and (table["raim_status"] == "valid").all()
    assert (hpe < table["hpl_gst_m"]).all(), (hpe, table["hpl_gst_m"].tolist())
    assert hpe.max() < 10.0  # a phone, single point, 6 satellites: metres, not tens


def test_rnx2rtkp_without_navigation_data_says_so(tmp_path):
    obs, nav = SHARED / "android" / "pixel6.23o", SHARED / "rinex" / "brdc1190.21n"
    _need_rtklib(obs, nav)
    out = tmp_path / "pixel6.pos"
    subprocess.run(["rnx2rtkp", "-p", "0", "-o", str(out), str(obs), str(nav)], capture_output=True, timeout=120)
    proc = run_cli("integrity", str(out))  # the 2023-11-07 session, a 2021-04-29 ephemeris: RTKLIB solves nothing
    assert proc.returncode == 1 and b"without one solution" in proc.stderr and b"navigation data" in proc.stderr
    info = run_cli("info", str(out), "--json")  # info describes it rather than failing
    assert info.returncode == 0 and '"epochs": 0' in info.stdout.decode() and "without one solution" in info.stdout.decode()
