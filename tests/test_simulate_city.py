"""The simulator's city drive (``--nlos``, ``--odometry``): reflected signals are weaker and late, the odometry has
its scale error and gyro bias, and the drive is written as libRSF text that the libRSF reader and the pseudorange
path read like the real Berlin drive; without the options nothing changes (the samples test holds the bytes)."""

from __future__ import annotations

import numpy as np
import pytest

from tollcli.geodesy import OMEGA_EARTH_RADPS, geodetic2ecef
from tollcli.gnss.librsf_positions import librsf_epochs
from tollcli.readers.librsf import read_librsf
from tollcli.simulate.drive import SimConfig
from tollcli.simulate.route import straight
from tollcli.simulate.run import write_drive

C = 299_792_458.0


@pytest.fixture(scope="module")
def city(tmp_path_factory):
    folder = tmp_path_factory.mktemp("city")
    trajectory = straight(48.137, 11.575, 30.0, 10.0, 600.0, 1.0)
    manifest = write_drive(trajectory, SimConfig(env="urban", nlos=True, odometry=True, seed=4), str(folder))
    return folder, manifest


def _errors(log, truth) -> tuple[np.ndarray, np.ndarray]:
    """Each pseudorange's error against the true range (receiver clock and Sagnac removed) and its C/N0."""
    d = log.pseudoranges
    at = np.searchsorted(truth["t_s"].to_numpy(), d["t_s"].to_numpy())
    pos = truth[["x_m", "y_m", "z_m"]].to_numpy()[at]
    s = d[["x_sv_m", "y_sv_m", "z_sv_m"]].to_numpy()
    th = OMEGA_EARTH_RADPS * np.linalg.norm(s - pos, axis=1) / C
    rot = np.stack([np.cos(th) * s[:, 0] + np.sin(th) * s[:, 1], -np.sin(th) * s[:, 0] + np.cos(th) * s[:, 1], s[:, 2]], 1)
    return d["pr_m"].to_numpy() - np.linalg.norm(rot - pos, axis=1) - 12_345.0, d["cn0_dbhz"].to_numpy()


def test_the_city_drive_is_written_as_librsf_and_read_like_berlin(city):
    folder, manifest = city
    assert {"drive-librsf.txt", "truth-librsf.txt"} <= set(manifest["files"])
    log, truth = read_librsf(str(folder / "drive-librsf.txt")), read_librsf(str(folder / "truth-librsf.txt")).points
    assert log.malformed == 0 and len(log.odometry) == len(truth) == 600
    epochs, meas = librsf_epochs(log)
    assert len(epochs) == 600 and (epochs["n_measurements"] >= 4).mean() > 0.9
    true = np.array(geodetic2ecef(48.137, 11.575, 0.0))
    assert np.linalg.norm(truth[["x_m", "y_m", "z_m"]].to_numpy()[0] - true) < 100.0


def test_reflected_signals_are_weak_and_late_and_direct_ones_are_not(city):
    folder, _ = city
    error, cn0 = _errors(read_librsf(str(folder / "drive-librsf.txt")), read_librsf(str(folder / "truth-librsf.txt")).points)
    weak, strong = cn0 < 32.0, cn0 >= 40.0
    assert weak.sum() > 200 and strong.sum() > 1000
    assert np.median(error[weak]) > 20.0 and (error[weak] > 0).mean() > 0.95  # an excess path: always late
    assert abs(np.median(error[strong])) < 3.0


def test_the_odometry_has_its_scale_error_and_gyro_bias(city):
    folder, _ = city
    odometry = read_librsf(str(folder / "drive-librsf.txt")).odometry
    moving = odometry["vx_mps"].to_numpy() > 1.0
    assert np.median(odometry["vx_mps"].to_numpy()[moving]) == pytest.approx(10.0 * 1.01, abs=0.01)
    assert np.mean(odometry["wz_radps"].to_numpy()[moving]) == pytest.approx(0.002, abs=0.0005)  # a straight road: the bias


def test_without_the_options_no_librsf_is_written(tmp_path):
    manifest = write_drive(straight(48.137, 11.575, 30.0, 10.0, 20.0, 1.0), SimConfig(seed=4), str(tmp_path))
    assert "drive-librsf.txt" not in manifest["files"] and not (tmp_path / "drive-librsf.txt").exists()
