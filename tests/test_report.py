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
    # the papers' ETC RAIM: its probable false alarms have a colour of their own in the figures
    result = run_cli("process", str(DRIVE / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "--raim", "etc", "-q", "-o", str(invoice))
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
    assert _has_colour(traj, "#1a9850") > 50 and _has_colour(traj, "#f4a6c0") > 50  # valid, probable false alarms
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


def test_probable_false_alarms_read_differently_from_credible_ones(tmp_path):
    """ETC RAIM on a clean urban drive: most alarms come at P_FA far above p_fa. They are
    ``probable_false_alarm`` in the epoch table, the invoice (with a note), the report (with the
    trade-off), and accuse nobody (no persistent-alarm finding); credible alarms keep ``fault_detected``."""
    clean = SAMPLES / "sim" / "urban-clean" / "drive.nmea"
    table = tmp_path / "integrity.csv"
    assert run_cli("integrity", str(clean), "--raim", "etc", "-q", "-o", str(table)).returncode == 0
    import pandas as pd

    epochs = pd.read_csv(table)
    probable = epochs["raim_status"] == "probable_false_alarm"
    credible = epochs["raim_status"] == "fault_detected"
    assert probable.sum() > 100 and (epochs["p_fa"][probable] > 5e-3).all() and (epochs["p_fa"][credible] <= 5e-3).all()
    classic = tmp_path / "classic.csv"
    assert run_cli("integrity", str(clean), "--raim", "classic", "-q", "-o", str(classic)).returncode == 0
    assert "probable_false_alarm" not in set(pd.read_csv(classic)["raim_status"])  # classic fixes P_FA = p_fa
    invoice = tmp_path / "invoice.json"
    assert run_cli("process", str(clean), "--geo", GEO, "--tariff", TARIFF, "--raim", "etc", "-q", "-o", str(invoice)).returncode == 0
    doc = json.loads(invoice.read_text())
    assert any("probable_false_alarm" in line["statuses"] for line in doc["lines"])
    assert "HPL = HAL" in doc["status_notes"]["probable_false_alarm"]
    assert not [f for f in doc["findings"]["items"] if f["kind"] == "raim_persistent_alarm"]
    page = tmp_path / "report.html"
    assert run_cli("report", str(invoice), "-q", "-o", str(page)).returncode == 0
    text = page.read_text()
    assert "What the epoch statuses mean" in text and "false alarms cost evidence" in text


def _figure_of(monkeypatch, draw, run_data):
    """The matplotlib figure a plot function draws (instead of its PNG)."""
    from tollcli.report import plots

    kept = {}
    monkeypatch.setattr(plots, "_save", lambda fig, outdir, name, fmt="png": kept.setdefault("fig", fig))
    draw(run_data, "unused")
    return kept["fig"]


def _texts(fig) -> str:
    return " | ".join(t.get_text() for ax in fig.axes for t in ax.texts) + " | ".join(t.get_text() for t in fig.texts)


def test_plots_frame_the_drive_say_when_empty_and_keep_titles_inside(tmp_path, monkeypatch):
    """A network with a geo-object 90° of longitude away: the trajectory is framed on the drive (not a strip
    across the world) and says a geo-object is outside; a log with no passage has 'nothing to show' panels;
    no title is clipped."""
    from tollcli.report import plots
    from tollcli.report.run_data import load_run

    doc = json.loads(Path(GEO).read_text())
    far = json.loads(json.dumps(doc["features"][0]))
    far["properties"]["id"] = "FAR-1"
    far["geometry"]["coordinates"] = [[[x - 90.0, y] for x, y in ring] for ring in far["geometry"]["coordinates"]]
    doc["features"].append(far)
    geo = tmp_path / "geo.geojson"
    geo.write_text(json.dumps(doc))
    invoice = tmp_path / "invoice.json"
    assert run_cli("process", str(DRIVE / "drive.nmea"), "--geo", str(geo), "--tariff", TARIFF, "-q", "-o", str(invoice)).returncode == 0
    fig = _figure_of(monkeypatch, plots._trajectory, load_run(str(invoice)))
    west, east = fig.axes[0].get_xlim()
    assert east - west < 0.1 and "1 of 3 geo-objects lie outside this view" in _texts(fig)
    # a drive that passes no geo-object: nothing to show per passage
    nowhere = tmp_path / "nowhere.geojson"
    nowhere.write_text(json.dumps({"type": "FeatureCollection", "features": [far]}))
    empty = tmp_path / "empty.json"
    assert run_cli("process", str(DRIVE / "drive.nmea"), "--geo", str(nowhere), "--tariff", TARIFF, "-q", "-o", str(empty)).returncode == 0
    run_data = load_run(str(empty))
    fig = _figure_of(monkeypatch, plots._valid_positions, run_data)
    assert "nothing to show: no geo-object passage" in _texts(fig)
    for draw in (plots._trajectory, plots._protection, plots._valid_positions):
        fig = _figure_of(monkeypatch, draw, run_data)
        fig.canvas.draw()
        box = fig.bbox
        for ax in fig.axes:
            extent = ax.title.get_window_extent()
            assert box.x0 <= extent.x0 and extent.x1 <= box.x1 and extent.y1 <= box.y1, (draw.__name__, ax.title.get_text())


def test_report_with_a_truth_shows_the_stanford_diagram_and_the_truth_line(run, tmp_path):
    page = tmp_path / "report.html"
    assert run_cli("report", str(run), "--truth", str(DRIVE / "truth.csv"), "-q", "-o", str(page)).returncode == 0
    text = page.read_text()
    assert 'alt="Stanford diagram' in text and "data:image/png;base64," in text
    assert '"truth":[[' in text and "L.polyline(d.truth" in text
    bare = tmp_path / "bare.html"
    assert run_cli("report", str(run), "-q", "-o", str(bare)).returncode == 0
    assert "Stanford diagram" not in bare.read_text()
