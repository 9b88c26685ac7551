"""The man pages in man/ are what the generator makes from the current CLI, and they render."""

import shutil
import subprocess

import pytest

from conftest import REPO
from tollcli.cli.manpage import manpages


def test_man_pages_are_current():
    pages = manpages()
    committed = {p.name for p in (REPO / "man").glob("*.1")}
    assert committed == set(pages), "run: python -m tollcli.cli.manpage man"
    for name, text in pages.items():
        assert (REPO / "man" / name).read_text(encoding="utf-8") == text, f"{name} is out of date: python -m tollcli.cli.manpage man"


def test_every_page_documents_the_exit_codes():
    for name, text in manpages().items():
        assert ".SH EXIT STATUS" in text and "\\fB3\\fR" in text and "max\\-bad" in text, name


@pytest.mark.skipif(shutil.which("man") is None, reason="man is not installed on this machine")
def test_man_renders():
    out = subprocess.run(["man", "-l", str(REPO / "man" / "tollcli-process.1")], capture_output=True, text=True,
                         env={"MANWIDTH": "80", "PATH": "/usr/bin:/bin"}, timeout=60)  # fmt: skip
    assert out.returncode == 0 and "EXIT STATUS" in out.stdout and "--tariff" in out.stdout
