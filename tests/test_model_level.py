"""The ``model`` evidence level: a receiver that reports only its satellites (GSA + GSV) or only its HDOP.

HPL = K_H(P_MD)·σ_major of the used satellites' geometry under the σ of the environment — the urban σ unless the
residuals measured open sky or ``--environment open`` declares it — valid iff HPL ≤ HAL; no fault detection, and
the audit counts such positions as unprotected against a fault."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
from conftest import REPO, SAMPLES, run_cli

from tollcli.gnss.sigma_models import NominalModel, sigma_for
from tollcli.integrity.model_bound import NOMINAL_WORST_SIGMA_M
from tollcli.integrity.raim import RaimParams
from tollcli.job.log_integrity import iter_integrity

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
RURAL = SAMPLES / "sim" / "rural-clean"


def _satellites_only(tmp_path, name: str = "rural-clean") -> str:
    """The simulator's drive as a receiver that writes GGA, RMC, GSA and GSV only (no GRS, GBS, GST)."""
    lines = (SAMPLES / "sim" / name / "drive.nmea").read_text().splitlines()
    log = tmp_path / f"{name}-gsa-gsv.nmea"
    log.write_text("\n".join(line for line in lines if line[3:6] in ("GGA", "RMC", "GSA", "GSV")) + "\n")
    return str(log)


def test_the_hdop_bounds_sigma_is_the_nominal_models_worst_satellite():
    elevations = np.array([5.0])
    worst = max(float(sigma_for("nominal", elev_deg=elevations, cn0_dbhz=np.array([np.nan]), lon_deg=np.zeros(1),
                                constellation=np.array([c], dtype=object), lat_deg=np.array([lat]), nominal=NominalModel())[0])
                for lat in np.arange(-90.0, 91.0, 5.0) for c in ("GPS", "Galileo", "GLONASS", "BeiDou"))  # fmt: skip
    assert worst <= NOMINAL_WORST_SIGMA_M < worst + 0.5


def _table(log: str, environment: str) -> pd.DataFrame:
    return pd.concat([c.table for c in iter_integrity(log, "nmea", RaimParams(), environment=environment)], ignore_index=True)


def test_satellites_only_is_the_model_level_urban_unless_open_is_declared_and_it_bounds_the_truth(tmp_path):
    log = _satellites_only(tmp_path)
    auto = _table(log, "auto")
    assert (auto["integrity_source"] == "model").all() and (auto["raim_status"] == "unavailable").all()
    assert (auto["hpl_model_m"] > 100).all()  # urban σ: ≥ 25 m a satellite
    opened = _table(log, "open")
    assert (opened["integrity_source"] == "model").all() and (opened["raim_status"] == "valid").mean() > 0.9
    truth = pd.read_csv(RURAL / "truth.csv")
    from tollcli.geodesy import great_circle_distance_m

    error = great_circle_distance_m(opened["lat_deg"].to_numpy(), opened["lon_deg"].to_numpy(), truth["lat_deg"].to_numpy(),
                                    truth["lon_deg"].to_numpy())  # fmt: skip
    valid = opened["raim_status"] == "valid"
    assert (error[valid] <= opened.loc[valid, "hpl_model_m"]).all()  # no misleading information on the papers' errors
    proc = run_cli("integrity", log, "-o", str(tmp_path / "i.csv"))  # the summary says what the level is worth
    assert proc.returncode == 0 and "model level: the satellites' geometry and an error model only, no fault detection" in proc.stderr.decode()


def test_a_model_level_charge_says_what_it_is_worth_and_the_audit_counts_it_unprotected(tmp_path):
    log = _satellites_only(tmp_path)
    invoice_path = tmp_path / "inv.json"
    proc = run_cli("process", log, "--geo", GEO, "--tariff", TARIFF, "--environment", "open", "-q", "-o", str(invoice_path))
    assert proc.returncode == 0, proc.stderr.decode()
    invoice = json.loads(invoice_path.read_text())
    assert invoice["lines"] and all(set(line["vouched_by"]) == {"model"} for line in invoice["lines"])
    assert invoice["parameters"]["integrity_sources_used"] == "model" and "no fault detection" in invoice["source_notes"]["model"]
    report = tmp_path / "risk.json"
    proc = run_cli("audit", str(invoice_path), "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(report))
    assert proc.returncode == 0, proc.stderr.decode()
    charges = json.loads(report.read_text())["charges"]
    assert charges and all(c["n_vouched"] == 0 and c["p_false_bound"] == 1.0 for c in charges)
    # the defaults (environment auto: no residuals, urban σ) charge nothing, and each passage says why in those words
    proc = run_cli("process", log, "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice_path))
    invoice = json.loads(invoice_path.read_text())
    assert invoice["total"] == "0.00" and invoice["not_charged"]
    assert all(p["why"].startswith("the receiver reports no integrity output") for p in invoice["not_charged"])


def test_integrity_sources_model_and_below_it(tmp_path):
    """``--integrity-sources covariance`` (or stricter) does not let the model bound validate: a satellites-only log is
    then unmonitored; ``model`` (what ``auto`` settles on for it) does."""
    log = _satellites_only(tmp_path)
    out = tmp_path / "i.csv"
    for level, expected in (("model", "valid"), ("auto", "valid"), ("covariance", "unmonitored"), ("residual", "unmonitored")):
        proc = run_cli("integrity", log, "--integrity-sources", level, "--environment", "open", "-q", "-o", str(out))
        assert proc.returncode == 0, proc.stderr.decode()
        table = pd.read_csv(out)
        assert (table["raim_status"] == expected).mean() > 0.9, (level, table["raim_status"].value_counts())
        assert table["hpl_model_m"].notna().all()


def test_a_differential_fix_gets_the_corrected_ionospheres_sigma():
    """GGA quality 2 (SBAS or ground corrections): paper 004's σ with the SBAS ionosphere, for the RAIM and the model
    level alike; the same satellites in an autonomous fix keep the single-frequency σ."""
    import io

    from tollcli.gnss.nmea_measurements import nmea_measurements
    from tollcli.readers.nmea import read_nmea
    from tollcli.readers.nmea.compose import straight_drive

    tables = read_nmea(io.BytesIO(("\n".join(straight_drive(3)) + "\n").encode()))
    autonomous = nmea_measurements(tables.epochs, tables.satellites)
    differential = nmea_measurements(tables.epochs.assign(fix_quality=np.int8(2)), tables.satellites)
    expected = sigma_for("nominal", elev_deg=tables.satellites["elev_deg"].to_numpy(float)[:1],
                         cn0_dbhz=tables.satellites["cn0_dbhz"].to_numpy(float)[:1], lon_deg=np.array([2.9]),
                         constellation=tables.satellites["constellation"].to_numpy(object)[:1], lat_deg=np.array([42.7]),
                         nominal=NominalModel(iono="sbas"))  # fmt: skip
    mask = autonomous.mask
    assert (differential.sigma_m[mask] < autonomous.sigma_m[mask]).all()
    assert np.nanmin(differential.sigma_m) <= expected[0] + 5 and np.nanmax(differential.sigma_m) < 5.0


def test_satellites_reported_without_their_angles_are_bounded_by_the_hdop_as_if_none_were(tmp_path):
    """gpsd reports a Javad GREIS receiver's satellites without elevations: no geometry to bound, so the receiver's
    HDOP bounds the fix (the ``model`` level), as it does a fix whose satellites are not reported at all — the same
    bound and verdict when the satellite lists are taken out (metamorphic), and never ``insufficient`` for want of
    angles the receiver did not give. (They were ``insufficient`` at every epoch before.)"""
    from conftest import shared

    chk = shared("gpsd", "greis-binary.log.chk")
    bare = tmp_path / "bare.json"
    lines = []
    for line in chk.read_text(encoding="utf-8").splitlines():
        if line.startswith('{"class":"SKY"'):
            report = json.loads(line)
            report.pop("satellites", None)
            line = json.dumps(report)
        lines.append(line)
    bare.write_text("\n".join(lines) + "\n")

    def table(path):
        chunks = list(iter_integrity(str(path), "gpsd-json", RaimParams()))
        return pd.concat([c.table for c in chunks], ignore_index=True)

    given, without = table(chk), table(bare)
    assert (given["raim_status"] != "insufficient").all() and (given["integrity_source"] == "model").sum() >= 40
    assert given["hpl_model_m"].notna().sum() >= 40
    np.testing.assert_array_equal(given["hpl_model_m"].to_numpy(float), without["hpl_model_m"].to_numpy(float))
    assert given["raim_status"].tolist() == without["raim_status"].tolist()
