"""Figures and the HTML audit page of a run; the page rendered in headless Chromium.

Screenshots and figures are kept in ``build/test-artifacts/`` for people to look at.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, SAMPLES, run_cli

ARTIFACTS = REPO / "build" / "test-artifacts"
GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
DRIVE = SAMPLES / "sim" / "urban-fault"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("run")
    invoice = folder / "invoice.json"
    result = run_cli("process", str(DRIVE / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "-q", "-o", str(invoice))
    assert result.returncode == 0, result.stderr.decode()
    return invoice


def _image(path: Path) -> np.ndarray:
    import matplotlib.image

    return matplotlib.image.imread(str(path))[..., :3]


def _has_colour(img: np.ndarray, hex_colour: str, tol: float = 0.06) -> int:
    rgb = np.array([int(hex_colour[i : i + 2], 16) / 255 for i in (1, 3, 5)])
    return int(np.sum(np.all(np.abs(img - rgb) < tol, axis=-1)))


def test_plot_writes_the_figures(run):
    out = ARTIFACTS / "plots"
    result = run_cli("plot", str(run), "--truth", str(DRIVE / "truth.csv"), "-q", "-o", str(out))
    assert result.returncode == 0, result.stderr.decode()
    for name in ("trajectory.png", "protection.png", "valid_positions.png", "stanford.png"):
        img = _image(out / name)
        assert img.shape[0] > 300 and img.std() > 0.05, name  # not blank
    traj = _image(out / "trajectory.png")
    assert _has_colour(traj, "#1a9850") > 50 and _has_colour(traj, "#d73027") > 50  # valid and fault_detected positions
    # without a truth there is no Stanford diagram
    bare = ARTIFACTS / "plots-no-truth"
    shutil.rmtree(bare, ignore_errors=True)
    assert run_cli("plot", str(run), "-q", "-o", str(bare)).returncode == 0
    assert sorted(p.name for p in bare.iterdir()) == ["protection.png", "trajectory.png", "valid_positions.png"]


def test_report_is_self_contained(run, tmp_path):
    page = tmp_path / "report.html"
    result = run_cli("report", str(run), "--truth", str(DRIVE / "truth.csv"), "-q", "-o", str(page))
    assert result.returncode == 0, result.stderr.decode()
    text = page.read_text()
    # nothing is fetched at view time: no external scripts, styles, images or fonts
    assert not re.search(r"""<(script|link|img|iframe)[^>]+(src|href)\s*=\s*["']?(https?:)?//""", text, re.I)
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", text, re.I)
    assert "L.tileLayer" in text and '"tiles":null' in text  # no background map unless asked for
    invoice = json.loads(run.read_text())
    assert f"<td>{invoice['total']}</td>" in text and "A9-N1" in text and "position_jump" in text
    assert "alarm_failure" in text  # the truth section
    # the same inputs give the same page
    again = tmp_path / "again.html"
    assert run_cli("report", str(run), "--truth", str(DRIVE / "truth.csv"), "-q", "-o", str(again)).returncode == 0
    assert again.read_bytes() == page.read_bytes()
    assert run_cli("report", str(run), "--tiles", "https://tiles.example/", "-o", str(tmp_path / "x.html")).returncode == 2


def _chromium(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={cwd / 'profile'}", "--hide-scrollbars",
             "--virtual-time-budget=5000"]  # fmt: skip
    return subprocess.run([CHROMIUM, *flags, *args], capture_output=True, timeout=120, cwd=cwd)


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium absent: install Debian's 'chromium' package (.ci/run does) to render the report")
def test_report_renders_in_headless_chromium(run, tmp_path):
    page = tmp_path / "report.html"
    assert run_cli("report", str(run), "--truth", str(DRIVE / "truth.csv"), "-q", "-o", str(page)).returncode == 0
    dom = _chromium("--dump-dom", page.as_uri(), cwd=tmp_path).stdout.decode()
    assert 'data-map-ready="yes"' in dom  # the map script ran to its end
    assert "leaflet-container" in dom and "<canvas" in dom and 'class="legend' in dom
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "report.png"
    result = _chromium("--window-size=1200,1100", f"--screenshot={shot}", page.as_uri(), cwd=tmp_path)
    assert shot.exists(), result.stderr.decode()[-500:]
    img = _image(shot)
    top = img[: int(img.shape[0] * 0.6)]  # the map fills the upper part of the page
    assert _has_colour(top, "#1a9850") > 30, "no valid positions drawn on the map"
    assert _has_colour(top, "#d73027") > 30, "no fault_detected positions drawn on the map"
    assert _has_colour(top, "#4575b4", tol=0.12) > 100, "no charged geo-object outline"


def test_plot_and_report_of_an_invoice_handed_over_with_its_files(tmp_path):
    """The auditor's folder: invoice, log and geo-objects side by side, opened from elsewhere; a changed log is refused."""
    work = tmp_path / "operator"
    (work / "logs").mkdir(parents=True)
    shutil.copy(DRIVE / "drive.nmea", work / "logs" / "drive.nmea")
    shutil.copy(GEO, work / "geo.geojson")
    made = run_cli("process", "logs/drive.nmea", "--geo", "geo.geojson", "--tariff", TARIFF, "-q", "-o", "invoice.json", cwd=work)
    assert made.returncode == 0, made.stderr.decode()
    handed = tmp_path / "case"
    handed.mkdir()
    for name in ("invoice.json", "logs/drive.nmea", "geo.geojson"):
        shutil.copy(work / name, handed / Path(name).name)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    assert run_cli("report", str(handed / "invoice.json"), "-q", "-o", str(tmp_path / "r.html"), cwd=elsewhere).returncode == 0
    result = run_cli("plot", str(handed / "invoice.json"), "-q", "-o", str(tmp_path / "figs"), cwd=elsewhere)
    assert result.returncode == 0, result.stderr.decode()
    (handed / "drive.nmea").write_text("changed\n")
    changed = run_cli("plot", str(handed / "invoice.json"), "-q", "-o", str(tmp_path / "figs2"), cwd=elsewhere)
    assert changed.returncode == 1 and "changed since the invoice was made" in changed.stderr.decode()
