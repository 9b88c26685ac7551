"""The README is a front page a newcomer reads (≤ 150 lines) and every document is found from the index."""

from __future__ import annotations

import re

from conftest import REPO


def test_the_readme_is_short_and_keeps_the_set_up_and_test_command():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    for marker in ("<!-- run-command -->", "<!-- test-command -->", "## Exit codes", "HAL", "HPL", "P_MD"):
        assert marker in text, marker
    assert "docs/README.md" in text


def test_every_document_is_in_the_index_and_every_link_resolves():
    index = (REPO / "docs" / "README.md").read_text(encoding="utf-8")
    linked = set(re.findall(r"\]\(([^)#]+)", index))
    for doc in (REPO / "docs").glob("*.md"):
        if doc.name != "README.md":
            assert doc.name in linked, f"docs/{doc.name} is not in docs/README.md"
    for target in linked:
        assert (REPO / "docs" / target).resolve().exists(), target
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)", readme):
        assert (REPO / target).exists(), target


def test_every_module_is_named_in_the_layout_and_every_named_module_exists():
    """docs/architecture.md's layout names every module of the package, and names no file that is not there; each
    package's own description names only files it holds."""
    package = REPO / "tollcli"
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    layout = text[text.index("## Layout"):]
    modules = [p for p in package.rglob("*.py") if p.name != "__init__.py" and "__pycache__" not in p.parts]
    unnamed = sorted(str(p.relative_to(REPO)) for p in modules if f"`{p.name}`" not in layout and f"{p.name}`" not in layout
                     and f"`{p.parent.name}/{p.name}`" not in layout)  # fmt: skip
    assert not unnamed, f"not named in docs/architecture.md's layout: {unnamed}"
    names = {p.name for p in modules} | {p.name for p in package.rglob("*.c")}
    for named in set(re.findall(r"`(?:[\w/]+/)?(\w+\.(?:py|c))`", layout)) - {"test_layering.py", "layering.py"}:
        assert named in names, f"docs/architecture.md names {named}, which is not in the package"
    for init in package.rglob("__init__.py"):
        held = {p.name for p in init.parent.rglob("*.py")} | {p.name for p in init.parent.rglob("*.c")}
        for named in set(re.findall(r"``?(\w+\.py)``?", init.read_text(encoding="utf-8"))):
            assert named in held or named.startswith("test_"), f"{init.relative_to(REPO)} names {named}, which it does not hold"


def _top_level_names(path) -> set[str]:
    import ast

    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
    return names


def test_every_dotted_name_in_the_code_and_the_docs_exists():
    """``tollcli.<room>.<module>[.<name>]`` in a docstring, comment or document names a module that is there and, after
    it, a name that module defines: a file moved or renamed leaves no description behind."""
    package = REPO / "tollcli"
    sources = [*package.rglob("*.py"), *(REPO / "docs").glob("*.md"), REPO / "README.md", REPO / "CONTRIBUTING.md",
               *(REPO / "tests").glob("*.py"), *(REPO / "benchmarks").glob("*.py")]  # fmt: skip
    stale = set()
    for source in sources:
        for dotted in set(re.findall(r"\btollcli(?:\.[A-Za-z_]\w*)+", source.read_text(encoding="utf-8"))):
            parts = dotted.split(".")[1:]
            where = package
            for k, part in enumerate(parts):
                if part.startswith("__"):  # a module's own attribute (__file__, __version__)
                    break
                if (where / part).is_dir():
                    where = where / part
                    continue
                if (where / f"{part}.c").exists():  # a compiled extension
                    break
                if (where / f"{part}.py").exists():
                    module = where / f"{part}.py"
                    rest = parts[k + 1 :]
                    if rest and rest[0] not in _top_level_names(module):
                        stale.add(f"{source.relative_to(REPO)}: {dotted} ({rest[0]} not in {module.relative_to(REPO)})")
                    break
                init = where / "__init__.py"
                if not (init.exists() and part in _top_level_names(init)):
                    stale.add(f"{source.relative_to(REPO)}: {dotted}")
                break
    assert not stale, "names of modules or functions that are not there:\n" + "\n".join(sorted(stale))
