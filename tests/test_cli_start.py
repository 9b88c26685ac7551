"""``tollcli`` and ``tollcli --help`` start at once: the list of commands comes from their summaries, no command module
(and so no numpy, pandas, scipy or the simulator) is imported; the list is the full application's, byte for byte."""

from __future__ import annotations

import subprocess
import sys

import click
import pytest
import typer
from conftest import REPO

from tollcli.cli.app import COMMANDS, SUMMARIES, build_app

HEAVY = ("numpy", "pandas", "scipy", "matplotlib", "shapely", "pyproj", "pyarrow", "tollcli.simulate", "tollcli.charging",
         "tollcli.integrity", "tollcli.readers")  # fmt: skip


def _help(app: typer.Typer) -> str:
    command = typer.main.get_command(app)
    return command.get_help(click.Context(command, info_name="tollcli", terminal_width=100, max_content_width=100))


def test_the_listing_is_the_full_applications_help():
    assert _help(build_app(listing=True)) == _help(build_app())


def test_each_summary_is_its_commands_own():
    full = typer.main.get_command(build_app())
    ctx = click.Context(full)
    assert set(SUMMARIES) == set(COMMANDS)
    for name in COMMANDS:
        assert (full.get_command(ctx, name).help or "").split("\n\n")[0] == SUMMARIES[name], name


@pytest.mark.parametrize("args", [["--help"], [], ["info", "--help"]])
def test_help_imports_no_heavy_module(args):
    probe = ("import sys\nfrom tollcli.cli.main import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
             f"print('imported:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))\n")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", probe, *args], capture_output=True, text=True, cwd=REPO, timeout=60)
    imported = r.stdout.rsplit("imported:", 1)[1].strip()
    assert imported == "", f"tollcli {' '.join(args)} imported {imported}"
    assert "Usage: tollcli" in r.stdout + r.stderr


def _collector_after(entry: str) -> tuple[bool, int]:
    """Whether the cyclic collector runs after ``entry`` (a call of main) ran ``process --help``, and how many objects
    it froze, in a process of its own."""
    probe = ("import gc, sys\nsys.argv = ['tollcli', 'process', '--help']\nfrom tollcli.cli.main import main\n"
             f"try:\n    {entry}\nexcept SystemExit:\n    pass\nprint('collector:', gc.isenabled(), gc.get_freeze_count())\n")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=REPO, timeout=60)
    enabled, frozen = r.stdout.rsplit("collector:", 1)[1].split()
    return enabled == "True", int(frozen)


def test_the_command_lines_own_run_freezes_what_its_imports_made_and_collects_again():
    """The console entry (main() reading sys.argv) makes no collection among a command's imports and freezes what they
    made (never scanned again: a tenth of a second of `process`); the collector runs again after. A caller giving main
    its arguments keeps its collector as it was: nothing of its own is frozen."""
    enabled, frozen = _collector_after("main()")
    assert enabled and frozen > 10_000  # a command's modules: tens of thousands of objects
    assert _collector_after("main(sys.argv[1:])") == (True, 0)


def test_a_quiet_epochs_run_imports_neither_rich_nor_pandas(tmp_path):
    """Reading a log into its tables needs numpy alone: `epochs -q` of an NMEA log imports no pandas, scipy or rich
    (the stderr console is made at its first note: a quiet run has none)."""
    from conftest import SAMPLES

    out = tmp_path / "epochs.csv"
    probe = ("import sys\nfrom tollcli.cli.main import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
             "print('imported:' + ','.join(m for m in ('pandas', 'scipy', 'rich', 'tollcli.charging', 'tollcli.integrity') "
             "if m in sys.modules))\n")  # fmt: skip
    log = SAMPLES / "sim" / "urban-fault" / "drive.nmea"
    r = subprocess.run([sys.executable, "-c", probe, "epochs", str(log), "-q", "-o", str(out)], capture_output=True, text=True,
                       cwd=REPO, timeout=120)  # fmt: skip
    assert r.returncode == 0 or "imported:" in r.stdout, r.stderr
    assert r.stdout.rsplit("imported:", 1)[1].strip() == ""
    assert out.read_text().startswith("epoch,time_utc,")
