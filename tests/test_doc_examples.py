"""Every command in the ``sh`` blocks of the README and of docs/ runs as written, and succeeds.

Each document's commands run in order (later ones read what earlier ones wrote) in a folder that looks like
the repository's root: ``samples/``, ``geoobjects/`` … linked in, ``../shared`` beside it when the shared data
is there, and ``.venv`` the environment running the tests — so the README's set-up (``. .venv/bin/activate``,
``man tollcli`` with the environment's ``share/man`` on MANPATH) runs as a newcomer types it. The install lines
(``<!-- run-command -->``, ``<!-- test-command -->``) are CI's own. ``text`` blocks are synopses and forms with
files of one's own: not run. A command that needs a program this machine lacks (gpsdecode, man) or the shared
data when it is absent is skipped, and the test says which.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
DOCUMENTS = [d for d in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), REPO / "samples" / "README.md"]
             if "```sh" in d.read_text(encoding="utf-8")]  # the others hold no command to run
#: blocks CI runs itself (the install and test lines)
CI_MARKERS = ("run-command", "test-command")
#: programs a command may need besides tollcli and the shell's own
OPTIONAL_PROGRAMS = ("gpsdecode", "man", "rnx2rtkp", "zcat", "gzip")


def sh_commands(text: str) -> list[str]:
    """The commands of a Markdown text's ``sh`` blocks (continuation lines joined; comments and blanks dropped)."""
    for marker in CI_MARKERS:
        text = re.sub(rf"<!-- {marker} -->.*?<!-- /{marker} -->", "", text, flags=re.S)
    commands: list[str] = []
    for block in re.findall(r"^```sh\n(.*?)^```", text, flags=re.S | re.M):
        pending = ""
        for line in block.splitlines():
            if pending:
                line = pending + " " + line.strip()
                pending = ""
            if line.rstrip().endswith("\\"):
                pending = line.rstrip()[:-1].rstrip()
                continue
            if line.strip() and not line.lstrip().startswith("#"):
                commands.append(line.strip())
    return commands


def test_the_examples_are_found():
    """The collector finds what it must: the README's examples, continuation lines joined, no install line."""
    assert {d.name for d in DOCUMENTS} >= {"README.md", "guide.md", "tariffs.md", "enforcement.md", "cli.md"}
    readme = sh_commands((REPO / "README.md").read_text(encoding="utf-8"))
    commands = sh_commands((REPO / "docs" / "cli.md").read_text(encoding="utf-8"))
    assert any(c.startswith("tollcli epochs samples/straight-drive.nmea -f parquet -o - |") for c in commands)
    assert "man tollcli" in readme and not any("pip install" in c for c in readme)
    guide = sh_commands((REPO / "docs" / "guide.md").read_text(encoding="utf-8"))
    assert any(c.startswith("tollcli process samples/sim/urban-fault/drive.nmea") and "--vehicle TRK-042" in c for c in guide)
    assert sh_commands("```sh\na \\\n  b\n# c\n```\n```text\nd\n```\n") == ["a b"]


def _sandbox(tmp_path: Path) -> Path:
    root = tmp_path / "tollcli"
    root.mkdir()
    for name in ("samples", "geoobjects", "docs", "benchmarks", "man", "tollcli"):
        (root / name).symlink_to(REPO / name)
    (root / ".venv").symlink_to(Path(sys.prefix))
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED)
    return root


@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_example_runs_as_written(doc, tmp_path):
    commands = sh_commands(doc.read_text(encoding="utf-8"))
    root = _sandbox(tmp_path)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "TOLLCLI_CACHE_DIR": str(tmp_path / "cache"), "MANPAGER": "cat", "PAGER": "cat"}
    env.pop("VIRTUAL_ENV", None)
    skipped, run = [], []
    for command in commands:
        words = set(re.findall(r"[A-Za-z][\w.-]*", command))
        missing = [p for p in OPTIONAL_PROGRAMS if p in words and shutil.which(p) is None]
        if "../shared/data" in command and not SHARED.is_dir():
            missing.append("../shared/data")
        if "man tollcli" in command and not (Path(sys.prefix) / "share" / "man" / "man1" / "tollcli.1").exists():
            missing.append("the man pages in this environment (an editable install has none: pip install .)")
        if missing:
            skipped.append(f"{command[:60]}… (needs {', '.join(missing)})")
        else:
            run.append(command)
    assert run, f"{doc.name}: nothing ran ({'; '.join(skipped)})"
    # one shell, as a reader types them: what a command sets up (an activated environment, MANPATH) holds for the next
    script = "set -eo pipefail\ntrap 'echo \"FAILED: $BASH_COMMAND\" >&2' ERR\n" + "\n".join(run) + "\n"
    proc = subprocess.run(["bash", "-c", script], cwd=root, env=env, capture_output=True, timeout=600)
    assert proc.returncode == 0, f"{doc.name}: exited {proc.returncode}: {proc.stderr.decode()[-800:]}"
    if skipped:
        print(f"{doc.name}: skipped " + "; ".join(skipped))


def test_man_pages_are_installed_with_the_package():
    """`pip install .` puts the man pages in the environment's share/man/man1 (what MANPATH points at)."""
    installed = Path(sys.prefix) / "share" / "man" / "man1"
    if not (installed / "tollcli.1").exists():
        direct_url = list(Path(sys.prefix).glob("lib/python*/site-packages/tollcli-*.dist-info/direct_url.json"))
        if direct_url and '"editable": true' in direct_url[0].read_text():
            pytest.skip("an editable install (pip install -e) installs no data files; CI installs with pip install .")
        pytest.fail(f"no man pages in {installed}")
    for page in (REPO / "man").glob("*.1"):
        assert (installed / page.name).read_bytes() == page.read_bytes(), f"{page.name} differs from the installed one"
    if shutil.which("man"):
        proc = subprocess.run(["man", "tollcli-process"], env={**os.environ, "MANPATH": str(installed.parent), "MANPAGER": "cat"},
                              capture_output=True, timeout=60)
        assert proc.returncode == 0 and b"process" in proc.stdout, proc.stderr
