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
