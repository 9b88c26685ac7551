"""An impossible σ never becomes a bound (issue 54's first finding): a GST or GBS sentence with a negative, zero or
infinite σ — checksum good — gives that source no verdict for its epoch, so a log whose only evidence is such a
GST is charged nothing, where a σ of −300 m used to charge 1.90 EUR with ``vouched_by: gst``."""

from __future__ import annotations

import json

import pytest
from conftest import REPO, SAMPLES, run_cli
from nmea_edit import edit_fields, sentence_type

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _with_gst_sigma(tmp_path, sigma: str) -> str:
    """The straight-drive sample with every GST's σ fields (semi-major, semi-minor, lat, lon) set to ``sigma``."""

    def edit(fields: list[str]) -> None:
        fields[3] = fields[4] = fields[6] = fields[7] = sigma

    lines = [edit_fields(line, edit) if sentence_type(line) == "GST" else line
             for line in (SAMPLES / "straight-drive.nmea").read_text().splitlines()]  # fmt: skip
    path = tmp_path / f"gst{sigma}.nmea"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def _charged(tmp_path, log: str) -> dict:
    out = tmp_path / "inv.json"
    done = run_cli("process", log, "--geo", GEO, "--tariff", TARIFF, "--integrity-sources", "covariance", "--policy", "raim",
                   "-q", "-o", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr.decode()
    return json.loads(out.read_text())


def test_a_sane_gst_sigma_still_charges(tmp_path):
    assert _charged(tmp_path, _with_gst_sigma(tmp_path, "3.00"))["lines"]


@pytest.mark.parametrize("sigma", ["-300.00", "-0.01", "0.00", "inf"])
def test_an_impossible_gst_sigma_charges_nothing(tmp_path, sigma):
    invoice = _charged(tmp_path, _with_gst_sigma(tmp_path, sigma))
    assert invoice["lines"] == [] and invoice["total"] in ("0.00", "0")
    assert all(status != "valid" for passage in invoice["not_charged"] for status in passage["statuses"])


def test_an_impossible_gbs_sigma_is_no_verdict():
    import numpy as np
    import pandas as pd

    from tollcli.gnss.receiver_outputs import receiver_outputs

    epochs = pd.DataFrame({"gbs_err_lat_m": [1.0, -1.0, 0.0, np.inf], "gbs_err_lon_m": [2.0, 2.0, 2.0, 2.0]})
    assert np.array_equal(receiver_outputs(epochs).gbs_sigma_major_m, [2.0, np.nan, np.nan, np.nan], equal_nan=True)


@pytest.mark.parametrize("sigma", ["0.0000", "-5.0000", "nan", "1e300"])
def test_an_impossible_rtklib_sigma_is_never_valid(tmp_path, sigma):
    """RTKLIB's sdn/sde (the 1σ north and east errors of a .pos file) zero, negative, NaN or absurd: no epoch valid on
    them (the real file's sdn/sde make every epoch valid)."""
    from conftest import shared

    lines = []
    for line in shared("rtklibexplorer", "gnss_1730_sf.pos").read_text().splitlines():
        if line.strip() and not line.startswith("%"):
            fields = line.split()
            fields[7] = fields[8] = sigma
            line = "  ".join(fields)
        lines.append(line)
    path = tmp_path / "bad.pos"
    path.write_text("\n".join(lines) + "\n")
    done = run_cli("integrity", str(path), "-o", str(tmp_path / "e.csv"), "--json", "-q")
    assert done.returncode == 0, done.stderr.decode()
    assert json.loads(done.stdout)["statuses"].get("valid", 0) == 0


@pytest.mark.parametrize("residual", ["99999999.9", "-99999999.9"])
def test_an_absurd_grs_residual_is_never_valid(tmp_path, residual):
    """A GRS residual of ±10⁸ m (checksum good) on one satellite of every epoch of a simulated drive whose residuals
    make all 230 epochs valid: the residual test fails there, no epoch is valid on it."""

    def edit(fields: list[str]) -> None:
        fields[3] = residual

    lines = [edit_fields(line, edit) if sentence_type(line) == "GRS" else line
             for line in (SAMPLES / "sim" / "rural-clean" / "drive.nmea").read_text().splitlines()]  # fmt: skip
    path = tmp_path / "grs.nmea"
    path.write_text("\n".join(lines) + "\n")
    done = run_cli("integrity", str(path), "-o", str(tmp_path / "e.csv"), "--json", "--integrity-sources", "residual", "-q")
    assert done.returncode == 0, done.stderr.decode()
    statuses = json.loads(done.stdout)["statuses"]
    assert statuses.get("valid", 0) == 0 and sum(statuses.values()) > 0, statuses


@pytest.mark.parametrize("h_acc_m,pl_m,valid", [(1.5, None, True), (0.0, None, False), (0.0, 0.0, False), (1.5, 4e6, False)])
def test_a_u_blox_accuracy_or_protection_level_that_is_no_sigma(tmp_path, h_acc_m, pl_m, valid):
    """NAV-PVT's hAcc and NAV-PL's horizontal protection level are the receiver's σ: 0 is no σ (no verdict), 4 000 km
    no bound within any HAL; 1.5 m makes every epoch valid (the control)."""
    import struct

    from test_ubx_nav import _nav_pvt

    from tollcli.readers.ubx_frames import frame

    data = b""
    for k in range(20):
        itow = 1000 * (43_200 + k)
        data += _nav_pvt(itow, 42.7 + k * 1e-4, 2.9, 9, h_acc_m=h_acc_m, second=k)
        if pl_m is not None:
            pl_mm = round(pl_m * 1000)
            data += frame(0x01, 0x62, struct.pack("<BBbBBBBBIIIII", 1, 1, -7, 1, 1, 0, 0, 0, 0, itow, pl_mm, pl_mm, pl_mm) + bytes(12))
    path = tmp_path / "nav.ubx"
    path.write_bytes(data)
    done = run_cli("integrity", str(path), "-o", str(tmp_path / "e.csv"), "--json", "-q")
    assert done.returncode == 0, done.stderr.decode()
    statuses = json.loads(done.stdout)["statuses"]
    assert (statuses.get("valid", 0) == 20) if valid else statuses.get("valid", 0) == 0, statuses
