"""``probable_false_alarm`` weighs the size of the exceedance: a test statistic no fault-free χ²_k reaches at
``p_fa`` is ``fault_detected`` however low the ETC threshold was (before: a 750 m outlier 250 000 × its threshold
was labelled 'no evidence of a fault' because the epoch's P_FA was high)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from conftest import REPO, run_cli
from scipy.stats import chi2

from tollcli.integrity.raim import FAULT, VALID
from tollcli.integrity.run import probable_false_alarms


def test_the_label_is_decided_by_the_chi2_tail_at_p_fa():
    dof = np.array([4, 4, 4, 4])
    limit = chi2.isf(5e-3, 4)  # 14.86
    t = np.array([limit * 0.99, limit * 1.01, 1e6, 3.0])
    status = np.array([FAULT, FAULT, FAULT, VALID])
    loose = np.array([0.9, 0.9, 0.9, 0.9])  # every epoch's threshold has P_FA 0.9 (a tight HAL)
    assert probable_false_alarms(status, t, dof, loose, 5e-3).tolist() == [True, False, False, False]
    strict = np.full(4, 1e-6)  # a threshold at a P_FA below p_fa: every alarm is credible
    assert not probable_false_alarms(status, t, dof, strict, 5e-3).any()


def test_a_750_m_fault_is_detected_not_excused_as_a_false_alarm(tmp_path):
    geo, roads = REPO / "geoobjects" / "example-geoobjects.geojson", REPO / "geoobjects" / "example-roads.geojson"
    r = run_cli("simulate", "--route", str(roads), "--via", "A9-N1", "--geo", str(geo), "--env", "rural", "--seed", "1",
                "--fault-bias", "750", "--fault-at", "30", "--fault-duration", "20", "-o", str(tmp_path / "sim"), "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = tmp_path / "epochs.csv"
    assert run_cli("integrity", str(tmp_path / "sim" / "drive.nmea"), "--raim", "etc", "--hal", "15", "-o", str(out), "-q").returncode == 0
    epochs = pd.read_csv(out)
    truth = pd.read_csv(tmp_path / "sim" / "truth.csv")
    faulty = truth["faulty"].to_numpy(bool)[: len(epochs)]
    status = epochs["raim_status"].to_numpy(str)
    assert faulty.sum() >= 15 and (status[faulty] == "fault_detected").all()
    # at HAL 15 m the ETC threshold fails the test often without a fault: those stay probable false alarms
    assert (status[~faulty] == "probable_false_alarm").sum() > 50 and (status[~faulty] == "fault_detected").sum() == 0
