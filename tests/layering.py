"""The package's rooms and the imports between its modules, read from the code (no module is imported).

A room imports only from rooms below it (lower rank); rooms of the same rank are
neighbours that do not import each other; inside a room, modules import each
other freely but without cycles. ``tollcli`` itself (``__version__``) and the
floor modules are rank 0, usable by every room.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

#: room → rank, in the order the data flows (the floor first, the CLI last)
ROOMS = {
    "floor": 0,  # tollcli/__init__, errors, times, cache, geodesy, spatial, stats, io/
    "readers": 1,  # tollcli/readers/: receiver files → tables
    "geoobjects": 1,  # tollcli/geoobjects/: road files → geo-objects, the compiled store (beside the readers)
    "gnss": 2,  # tollcli/gnss/: orbits, atmosphere, positioning, error models, measurements
    "integrity": 3,  # tollcli/integrity/: RAIM, FDE, design, speed, map matching, HIT, policies
    "charging": 4,  # tollcli/charging/: recognition, tariffs, invoices, audit
    "enforcement": 4,  # tollcli/enforcement/: locate, findings, roadside checks
    "job": 5,  # tollcli/job/: one log and many, end to end
    "simulate": 5,  # tollcli/simulate/: drives with known truth
    "report": 6,  # tollcli/report/: plots and HTML
    "cli": 7,  # tollcli/cli/ and tollcli/__main__
}
FLOOR_MODULES = {"tollcli", "tollcli.errors", "tollcli.times", "tollcli.cache", "tollcli.geodesy", "tollcli.spatial", "tollcli.kernels",
                 "tollcli.stats"}  # fmt: skip
PACKAGE_ROOMS = {"io": "floor", "readers": "readers", "geoobjects": "geoobjects", "gnss": "gnss", "integrity": "integrity", "charging": "charging",
                 "enforcement": "enforcement", "job": "job", "simulate": "simulate", "report": "report", "cli": "cli"}  # fmt: skip


@dataclass(frozen=True)
class Edge:
    source: str  # importing module
    target: str  # imported module
    line: int

    def __str__(self) -> str:
        return f"{self.source}:{self.line} imports {self.target}"


def module_name(root: Path, path: Path) -> str:
    """``tollcli/gnss/wls.py`` → ``tollcli.gnss.wls`` (a package's ``__init__`` is the package)."""
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def room_of(module: str) -> str:
    """The room a module lives in."""
    if module in FLOOR_MODULES:
        return "floor"
    parts = module.split(".")
    if parts[1] == "__main__":
        return "cli"
    room = PACKAGE_ROOMS.get(parts[1])
    if room is None:
        raise KeyError(f"{module}: in no room (add it to tests/layering.py)")
    return room


def modules(root: Path) -> dict[str, Path]:
    return {module_name(root, p): p for p in sorted(root.rglob("*.py"))}


def _bound_names(init: Path) -> set[str]:
    """Names a package's ``__init__`` binds at its top level (defined, assigned or imported)."""
    names = set()
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def edges(root: Path) -> list[Edge]:
    """Every import of one of the package's modules by another, at any depth of the code (also inside functions)."""
    known = modules(root)
    out = []
    for name, path in known.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                # `from pkg import sub` imports the submodule pkg.sub; `from mod import name` imports mod;
                # `from pkg import _ext`, a compiled module (not a name of pkg/__init__), imports nothing here
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known
                           else None if base in known and known[base].name == "__init__.py"
                           and a.name not in _bound_names(known[base]) else base
                           for a in node.names]  # fmt: skip
            for target in targets:
                while target and target not in known:  # `import tollcli.gnss.wls` → that module
                    target = target.rpartition(".")[0]
                if target and target.split(".")[0] == root.name and target != name:
                    out.append(Edge(name, target, node.lineno))
    return out


def upward_imports(root: Path) -> list[Edge]:
    """Imports from a room above the importer's own, or from a neighbour room of the same rank."""
    bad = []
    for e in edges(root):
        src, dst = room_of(e.source), room_of(e.target)
        if src != dst and ROOMS[dst] >= ROOMS[src]:
            bad.append(e)
    return bad


def cycles(root: Path) -> list[list[str]]:
    """Groups of modules that import each other, directly or round a loop (Tarjan's strongly connected components).

    A package's ``__init__`` that re-exports its submodules, imported by those submodules
    for a sibling (``from tollcli.readers.nmea import kernels``), counts as the sibling.
    """
    graph: dict[str, set[str]] = {m: set() for m in modules(root)}
    for e in edges(root):
        graph[e.source].add(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found
