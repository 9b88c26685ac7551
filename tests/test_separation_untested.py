"""``process`` solves the solution separation only where a verdict reads it (:func:`tollcli.integrity.run.separation_read`),
and the ``model`` level's HPL only where its level can decide (:func:`tollcli.integrity.run.model_level_read`).

An epoch without range residuals and without a statistic (a receiver that writes no GRS: GBS, GST or the model
level decide) has no residual test, and its status falls to ``unmonitored`` whatever its HPL; ``process`` without map
matching or an epoch table reads nothing else of it, so it is not solved there. These tests hold that the statuses,
every other RAIM column and the invoices are those of the separation solved everywhere.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, SAMPLES, shared

from tollcli.charging.invoice import invoice_json
from tollcli.gnss.nmea_measurements import nmea_measurements
from tollcli.gnss.wls import wls_geometry
from tollcli.integrity import run
from tollcli.integrity.raim import RaimParams
from tollcli.job import pipeline
from tollcli.job.pipeline import ChargeSettings, charge_log
from tollcli.readers.nmea import read_nmea

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")


def _both(meas, params, geometry):
    """The RAIM table with the separation solved everywhere, and with it solved only where read."""
    out = []
    for untested in (True, False):
        terms = run.hal_free_terms(meas, params, geometry, untested=untested)
        out.append((terms, run.run_raim(meas, params, geometry=geometry, hal_free=terms)))
    return out


def _nmea_logs():
    """Every gpsd regression log the NMEA reader gives epochs from."""
    for path in sorted(shared("gpsd").glob("*.log")):
        try:
            tables = read_nmea(str(path))
        except Exception:  # a binary protocol's log (SiRF, UBX, TSIP …): not NMEA
            continue
        if len(tables.epochs):
            yield path.name, tables


def test_every_real_nmea_logs_statuses_are_the_same_when_unread_epochs_are_not_solved():
    """All of ../shared/data/gpsd's NMEA logs: every RAIM column but ``hpl_m`` the same, ``hpl_m`` the same where read;
    at HAL 5 m many unread epochs have an HPL above it (their test's "unavailable" against "unmonitored" is at stake)."""
    logs = epochs = read_epochs = above = 0
    for name, tables in _nmea_logs():
        meas = nmea_measurements(tables.epochs, tables.satellites)
        geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
        residual, _ = run.post_fit_residuals(meas.H, geometry, meas.mask, meas.dy_m, meas.residual_m)
        read = run.separation_read(meas, run.wsse(residual, geometry))
        for hal_m in (50.0, 5.0):
            params = RaimParams(mode="ss", hal_m=hal_m)
            (full_terms, full), (part_terms, part) = _both(meas, params, geometry)
            pd.testing.assert_frame_equal(full.drop(columns="hpl_m"), part.drop(columns="hpl_m"), obj=name)
            np.testing.assert_array_equal(part["hpl_m"].to_numpy()[read], full["hpl_m"].to_numpy()[read], err_msg=name)
            assert np.isnan(part_terms.separation.hpl_m[~read]).all(), name
            above += int((full_terms.separation.hpl_m[~read] > hal_m).sum()) if hal_m == 5.0 else 0
        logs, epochs, read_epochs = logs + 1, epochs + read.size, read_epochs + int(read.sum())
    # 97 logs, 2 203 epochs, 37 of them with a residual test (GRS) or a statistic (GST); 874 unread ones above 5 m
    assert logs >= 90 and epochs >= 2000 and 0 < read_epochs < epochs and above > 500


def _stripped(tmp_path, sample: str, drop: tuple[str, ...]) -> str:
    """A sample log without the sentences ``drop`` (GRS: no residuals; GST too: nor a statistic)."""
    lines = (SAMPLES / sample).read_text().splitlines(keepends=True)
    out = tmp_path / f"{sample.replace('/', '-')}-{'-'.join(drop)}.nmea"
    out.write_text("".join(line for line in lines if line[3:6] not in drop))
    return str(out)


@pytest.mark.parametrize("sample", ["sim/urban-fault/drive.nmea", "sim/rural-clean/drive.nmea", "straight-drive.nmea"])
@pytest.mark.parametrize("drop", [(), ("GRS",), ("GRS", "GST")])
def test_invoices_are_the_same_when_unread_epochs_are_not_solved(tmp_path, monkeypatch, sample, drop):
    log = _stripped(tmp_path, sample, drop)
    calls = []
    solve_all = run.hal_free_terms

    def spy(meas, params, geometry, model_hpl_m=None, untested=True):
        calls.append(untested)
        return solve_all(meas, params, geometry, model_hpl_m, untested=everywhere)

    monkeypatch.setattr(pipeline, "hal_free_terms", spy)
    invoices = []
    for everywhere in (True, False):
        invoices.append(invoice_json(charge_log(log, GEO, TARIFF, ChargeSettings(), roads=None)[0]))
    assert invoices[0] == invoices[1]
    assert calls and not any(calls)  # process without map matching asked for the unread epochs to be left
    invoice = json.loads(invoices[0])
    assert invoice["lines"] or invoice["not_charged"]  # passages seen: the comparison covers positions


def test_every_real_nmea_logs_verdicts_are_the_same_without_an_unread_model_hpl():
    """All of ../shared/data/gpsd's NMEA logs, at the level each settles on: where that level has no ``model`` source,
    the model HPL left unsolved (NaN, as ``process`` leaves it without an epoch table) changes no column but
    ``hpl_model_m``; where it has one, :func:`run.model_level_read` says it is read."""
    unread = at_stake = read = 0
    for name, tables in _nmea_logs():
        meas = nmea_measurements(tables.epochs, tables.satellites)
        geometry = wls_geometry(meas.H, meas.sigma_m, meas.mask)
        for hal_m in (50.0, 5.0):
            params = run.settle_sources(RaimParams(mode="ss", hal_m=hal_m), meas)
            solved = run.hal_free_terms(meas, params, geometry)
            if run.model_level_read(params):
                assert params.sources is None or "model" in params.sources, name
                read += 1
                continue
            nan = run.HalFreeTerms(solved.separation, np.full(meas.mask.shape[0], np.nan))
            full = run.run_raim(meas, params, geometry=geometry, hal_free=solved)
            part = run.run_raim(meas, params, geometry=geometry, hal_free=nan)
            pd.testing.assert_frame_equal(full.drop(columns="hpl_model_m"), part.drop(columns="hpl_model_m"), obj=name)
            unread += 1
            at_stake += int((full["hpl_model_m"] > hal_m).any())  # the model would have denied there
    # 5 logs at the receiver (GBS) or covariance (GST) level leave it unread, at both HALs; 92 at the model level or
    # none read it; at 5 m, 4 of the unread have a model HPL above the HAL (its "unavailable" set aside is at stake)
    assert unread >= 8 and at_stake >= 3 and read >= 150


@pytest.mark.parametrize("sample", ["sim/urban-fault/drive.nmea", "straight-drive.nmea"])
@pytest.mark.parametrize("drop", [(), ("GRS",), ("GRS", "GST")])
def test_invoices_are_the_same_when_an_unread_model_hpl_is_not_solved(tmp_path, monkeypatch, sample, drop):
    log = _stripped(tmp_path, sample, drop)
    solved = []
    model_hpl = pipeline.model_hpl
    monkeypatch.setattr(pipeline, "model_hpl", lambda *a, **kw: (solved.append(1), model_hpl(*a, **kw))[1])
    invoices, counts = [], []
    for everywhere in (True, False):
        monkeypatch.setattr(pipeline, "model_level_read", (lambda params: True) if everywhere else run.model_level_read)
        solved.clear()
        invoices.append(invoice_json(charge_log(log, GEO, TARIFF, ChargeSettings(), roads=None)[0]))
        counts.append(len(solved))
    assert invoices[0] == invoices[1]
    level = json.loads(invoices[0])["parameters"]["integrity_sources_used"]
    assert counts[0] > 0
    assert counts[1] == (counts[0] if level == "model" else 0), level  # solved only where the level has the model


def test_map_matching_and_epoch_tables_still_get_every_epochs_hpl(monkeypatch):
    calls = []
    solve = run.hal_free_terms
    monkeypatch.setattr(pipeline, "hal_free_terms", lambda *a, **kw: (calls.append(kw.get("untested")), solve(*a, **kw))[1])
    log = str(SAMPLES / "sim" / "urban-clean" / "drive.nmea")
    charge_log(log, GEO, TARIFF, ChargeSettings(), roads=str(REPO / "geoobjects" / "example-roads.geojson"))
    table = []
    charge_log(log, GEO, TARIFF, ChargeSettings(), epoch_table=table)
    assert calls and all(calls)
    assert np.isfinite(table[0]["hpl_model_m"].to_numpy(float)).mean() > 0.9  # the epoch table's model HPL, solved
