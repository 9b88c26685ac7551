"""The rooms hold: no module imports from a room above its own, no import cycles, small files, documented rooms."""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

from layering import ROOMS, cycles, edges, modules, room_of, upward_imports

PACKAGE = Path(__file__).resolve().parents[1] / "tollcli"
LONG_LINES = 400


def test_every_module_is_in_a_room():
    for name in modules(PACKAGE):
        assert room_of(name) in ROOMS


def test_no_module_imports_from_a_room_above_its_own():
    bad = [f"{e} ({room_of(e.source)} → {room_of(e.target)})" for e in upward_imports(PACKAGE)]
    assert not bad, "imports against the flow of the data:\n" + "\n".join(bad)


def test_no_import_cycles():
    assert cycles(PACKAGE) == []


def test_the_checks_see_imports_inside_functions_and_relative_ones(tmp_path):
    """The layering test can fail: an upward import planted in a copy of the package is found, and a cycle too."""
    copy = tmp_path / "tollcli"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    assert upward_imports(copy) == [] and cycles(copy) == []
    raim = copy / "integrity" / "raim.py"
    raim.write_text(raim.read_text() + "\n\ndef _planted():\n    from tollcli.charging.invoice import seal\n")
    speed = copy / "integrity" / "speed.py"
    speed.write_text(speed.read_text() + "\n\ndef _planted():\n    from ..job import pipeline\n")
    found = {(e.source, e.target) for e in upward_imports(copy)}
    assert found == {("tollcli.integrity.raim", "tollcli.charging.invoice"), ("tollcli.integrity.speed", "tollcli.job.pipeline")}
    wls = copy / "gnss" / "wls.py"
    wls.write_text(wls.read_text() + "\n\ndef _planted():\n    import tollcli.gnss.pseudorange_wls\n")
    assert ["tollcli.gnss.pseudorange_wls", "tollcli.gnss.wls"] in cycles(copy)


def test_neighbour_rooms_do_not_import_each_other(tmp_path):
    copy = tmp_path / "tollcli"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    findings = copy / "enforcement" / "findings.py"
    findings.write_text(findings.read_text() + "\n\ndef _planted():\n    from tollcli.charging import tariffs\n")
    assert [(e.source, e.target) for e in upward_imports(copy)] == [("tollcli.enforcement.findings", "tollcli.charging.tariffs")]


def test_the_floor_and_the_readers_are_found_where_the_rooms_say():
    rooms = {name: room_of(name) for name in modules(PACKAGE)}
    assert rooms["tollcli.spatial"] == rooms["tollcli.io.sources"] == "floor"
    assert rooms["tollcli.readers.nmea.reader"] == rooms["tollcli.readers.rinex"] == "readers"
    assert rooms["tollcli.gnss.orbits"] == "gnss" and rooms["tollcli.integrity.raim"] == "integrity"
    assert rooms["tollcli.job.pipeline"] == "job" and rooms["tollcli.__main__"] == "cli"
    assert any(e.source == "tollcli.job.pipeline" and e.target == "tollcli.charging.invoice" for e in edges(PACKAGE))


def test_every_package_says_what_its_room_holds_and_may_use():
    for init in sorted(PACKAGE.rglob("__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))) or ""
        assert len([line for line in doc.splitlines() if line.strip()]) >= 2, f"{init}: a two-line docstring"
        if init.parent != PACKAGE:
            assert "uses" in doc.lower() or "may use" in doc.lower(), f"{init}: say what the room may use"


def test_long_modules_say_why_at_the_top():
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > LONG_LINES and "Why this file is long:" not in (ast.get_docstring(ast.parse(text)) or ""):
            unexplained.append(f"{path.relative_to(PACKAGE)}: {text.count(chr(10))} lines")
    assert not unexplained, "over ~400 lines without 'Why this file is long:' in the module docstring: " + ", ".join(unexplained)


def test_no_cli_module_computes():
    """The CLI parses options and calls the rooms below: no command module imports numpy or scipy (the arithmetic
    lives in the rooms below), and none reads a log itself (through io.log_run or a job function)."""
    import ast

    cli = Path(__file__).resolve().parent.parent / "tollcli" / "cli"
    for module in sorted(cli.glob("*.py")):
        tree = ast.parse(module.read_text(encoding="utf-8"))
        imported = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
        imported |= {(node.module or "").split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        assert not imported & {"numpy", "scipy"}, f"{module.name} computes: it imports {sorted(imported & {'numpy', 'scipy'})}"
        called = {node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
        assert not called & {"iter_navigation_tables", "pseudorange_epochs", "read_nmea"}, f"{module.name} reads a log itself"
