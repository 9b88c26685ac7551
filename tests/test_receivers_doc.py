"""docs/receivers.md is what the current code gives on every gpsd log, and every finding there is judged."""

from __future__ import annotations

import importlib.util

from conftest import REPO, shared


def _script():
    spec = importlib.util.spec_from_file_location("receivers_table", REPO / "docs" / "receivers_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_receivers_doc_is_generated_from_the_current_code():
    script = _script()
    text = script.render(shared("gpsd"))  # raises when a finding is not judged, or a judged one is gone
    assert (REPO / "docs" / "receivers.md").read_text(encoding="utf-8") == text, "stale: run python docs/receivers_table.py"


def test_no_real_receiver_is_accused_for_its_gst_rms_field():
    # u-blox ZED-F9P/F9T write GST RMS values of 10⁵ m beside a 2–4 m ellipse: ignored, never a fault, and their
    # own RAIM (GBS) vouches for the positions; no gpsd log has a raim_persistent_alarm or any spoofing sign from it
    rows = {r["log"]: r for r in (_script().log_row(p) for p in sorted(shared("gpsd").glob("ublox-zed-f9*.log"))) if r}
    f9p = rows["ublox-zed-f9p-nmea.log"]
    assert f9p["statuses"] == "29 valid (gbs)" and f9p["gst_rms_ignored"] == 29 and f9p["findings"] == ""
    f9t = rows["ublox-zed-f9t-ubx_nmea_l5.log"]
    # read as recognised (its UBX NAV-SAT prRes: the residual test, stricter than its GBS) it is valid throughout; its
    # GBS naming G08 with a 12.6 m bias of σ 219.6 m is no fault either (test_integrity_sources reads its NMEA)
    assert f9t["format"] == "ubx-nav" and f9t["statuses"] == "9 valid (grs)" and f9t["findings"] == ""
