"""The snapshot WLS of a pseudorange log solved a block of epochs at a time (``pseudorange_wls.BLOCK_EPOCHS``) is the
whole log's, bit for bit: every epoch's position, every measurement's σ, residual, angle and observation matrix — on
the real Berlin drive (libRSF), the GSDC 2022 phone file with the day's broadcast orbits, and a RINEX log whose
ionosphere (Klobuchar) and troposphere are corrected block by block, with blocks of 1, 7 and 500 epochs against the
default."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from conftest import shared

from tollcli.gnss import pseudorange_wls
from tollcli.gnss.pseudorange_inputs import pseudorange_epochs
from tollcli.gnss.sigma_models import NominalModel

LOGS = {
    "berlin": (("smartloc", "Berlin_Potsdamer_Platz_Input.txt"), "librsf", None),
    "gsdc2022 with orbits": (("gsdc2022", "device_gnss.csv"), "device-gnss", ("rinex", "brdc1190.21n")),
    "rinex": (None, "rinex", None),
}


def _solved(log, kind, nav):
    return pseudorange_epochs(str(log), kind, None if nav is None else str(nav), "nominal", 5.0, NominalModel())


@pytest.mark.parametrize("name", list(LOGS))
def test_the_snapshot_solution_is_the_same_whatever_the_block(monkeypatch, tmp_path, name):
    log, kind, nav = LOGS[name]
    if kind == "rinex":
        from rinex_synth import make_rinex

        log, nav, _ = make_rinex(tmp_path, n_epochs=30, noise_m=0.5, seed=3)
    else:
        log, nav = shared(*log), None if nav is None else shared(*nav)
    epochs, meas = _solved(log, kind, nav)
    assert np.isfinite(epochs["lat_deg"].to_numpy(float)).sum() > 0
    sizes = (7, 500) if name == "berlin" else (1, 7)  # (a long log one epoch at a time: slow, nothing more)
    for size in sizes:
        monkeypatch.setattr(pseudorange_wls, "BLOCK_EPOCHS", size)
        other_epochs, other_meas = _solved(log, kind, nav)
        for column in epochs.columns:
            a, b = epochs[column].to_numpy(), other_epochs[column].to_numpy()
            assert (np.array_equal(a, b, equal_nan=True) if a.dtype.kind in "fc" else (a == b).all()), (name, size, column)
        for field in dataclasses.fields(meas):
            a, b = getattr(meas, field.name), getattr(other_meas, field.name)
            if isinstance(a, np.ndarray):
                assert a.shape == b.shape and (np.array_equal(a, b, equal_nan=True) if a.dtype.kind in "fc" else (a == b).all()), \
                    (name, size, field.name)  # fmt: skip


def test_blocks_cover_every_epoch_once():
    for n in (0, 1, 4095, 4096, 4097, 10_000):
        rows = pseudorange_wls.blocks(n)
        covered = np.concatenate([np.arange(n)[r] for r in rows]) if n else np.zeros(0, int)
        assert (covered == np.arange(n)).all() and all(r.stop - r.start <= pseudorange_wls.BLOCK_EPOCHS for r in rows)


def test_an_epoch_with_fewer_measurements_than_unknowns_is_no_fix(tmp_path):
    """Berlin's first 200 epochs with one epoch cut to three GPS pseudoranges and one Galileo: four measurements of five
    unknowns (the position and two clocks). Its solution never left the iteration's start, hundreds of kilometres
    away, and was written as a fix; it is no fix now (the RAIM calls it insufficient), and every other epoch is as
    it was."""
    lines = shared("smartloc", "Berlin_Potsdamer_Platz_Input.txt").read_text().splitlines()
    times = sorted({float(line.split()[1]) for line in lines if line.startswith("pseudorange3")})[:200]
    cut_at = times[100]
    kept, gps, galileo = [], 0, 0
    for line in lines:
        fields = line.split()
        if fields[0] not in ("pseudorange3", "odom3") or float(fields[1]) > times[-1]:
            continue
        if fields[0] == "pseudorange3" and float(fields[1]) == cut_at:
            is_galileo = int(float(fields[7])) >= 300  # (satellite number: Galileo 300 + PRN)
            if (galileo if is_galileo else gps) >= (1 if is_galileo else 3):
                continue
            galileo, gps = galileo + is_galileo, gps + (not is_galileo)
        kept.append(line)
    assert (gps, galileo) == (3, 1)
    log = tmp_path / "cut.txt"
    log.write_text("\n".join(kept) + "\n")
    epochs, meas = pseudorange_epochs(str(log), "librsf", None, "nominal", 5.0, NominalModel())
    seconds = (epochs["time_utc"] - pd.Timestamp("1970-01-01", tz="UTC")).dt.total_seconds().to_numpy()  # (libRSF: from 1970)
    row = int(np.flatnonzero(np.isclose(seconds, cut_at))[0])
    assert meas.mask[row].sum() == 4 and np.isnan(epochs["lat_deg"].iat[row])
    assert np.isfinite(np.delete(epochs["lat_deg"].to_numpy(), row)).all()
    assert pseudorange_wls.solvable(meas.mask, meas.clock_index).tolist() == np.isfinite(epochs["lat_deg"].to_numpy()).tolist()
