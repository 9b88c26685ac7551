"""Terminal output: tables for people on a terminal, colours off with NO_COLOR, nothing extra in pipes."""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys

from conftest import REPO, SAMPLES, run_cli

GEO = str(REPO / "geoobjects" / "example-geoobjects.geojson")
TARIFF = str(REPO / "geoobjects" / "example-tariff.toml")
COLOUR = r"\x1b\[(?:[0-9;]*;)?(?:3[0-8]|9[0-7]|4[0-8])(?:;[0-9;]*)?m"  # an SGR sequence that sets a colour
DRIVE = str(SAMPLES / "sim" / "urban-fault" / "drive.nmea")


def _on_a_terminal(*args: str, no_color: bool) -> str:
    """Run the CLI with stdout and stderr on a pseudo-terminal; what the user would see."""
    master, slave = pty.openpty()
    env = dict(os.environ, COLUMNS="160", TERM="xterm-256color")
    env.pop("NO_COLOR", None)
    if no_color:
        env["NO_COLOR"] = "1"
    proc = subprocess.Popen([sys.executable, "-m", "tollcli", *args], stdout=slave, stderr=slave, cwd=REPO, env=env)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=120)
    os.close(master)
    return b"".join(chunks).decode("utf-8", "replace")


def test_process_on_a_terminal_shows_the_invoice_and_statuses_in_colour():
    seen = _on_a_terminal("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "--raim", "etc", "-o", "-", no_color=False)
    assert "Invoice" in seen and "TOTAL" in seen and "2.38" in seen
    assert "by RAIM status" in seen and "probable_false_alarm" in seen and "Findings" in seen
    assert "no evidence of a fault" in " ".join(seen.split())  # the trade-off, where the auditor sees the statuses
    assert re.findall(COLOUR, seen)  # colours


def test_no_color_turns_colours_off():
    seen = _on_a_terminal("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-o", "-", no_color=True)
    colours = re.findall(COLOUR, seen)
    assert "TOTAL" in seen and colours == []  # bold and italic stay; no foreground or background colour


def test_audit_on_a_terminal_lists_causes(tmp_path):
    inv = tmp_path / "inv.json"
    assert run_cli("process", str(SAMPLES / "sim" / "urban-clean" / "drive.nmea"), "--geo", GEO, "--tariff", TARIFF, "--p-md", "1e-9",
                   "-q", "-o", str(inv)).returncode == 0  # fmt: skip
    seen = _on_a_terminal("audit", str(inv), "--truth", str(SAMPLES / "sim" / "urban-clean" / "truth-geoobjects.json"), "-o", str(tmp_path / "a.json"),
                          no_color=True)  # fmt: skip
    assert "Audit against the truth" in seen and "A9-N1" in seen


def test_pipes_get_no_tables():
    result = run_cli("process", DRIVE, "--geo", GEO, "--tariff", TARIFF, "-o", "-")
    assert result.stdout.startswith(b"{") and b"TOTAL" not in result.stderr and b"\x1b[" not in result.stderr
