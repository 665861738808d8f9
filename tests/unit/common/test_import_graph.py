"""The import graph of the product: no cycle between modules or between rooms, the
layers one-way, and rooms of a size a reader can take in (docs/architecture.md).

Every import counts: module level, inside functions, and under ``if TYPE_CHECKING:``
(a cycle of type imports is still two modules that cannot be read one before the other).
The graph is read from the source with :mod:`ast`; nothing is imported.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest
from conftest import ROOT

PACKAGES = ("swarm_common", "vehicle_sim", "offboard", "gcs")
# which top-level packages each may import (one-way layers)
ALLOWED = {
    "swarm_common": {"swarm_common"},
    "vehicle_sim": {"swarm_common", "vehicle_sim"},
    "offboard": {"swarm_common", "offboard"},
    "gcs": {"swarm_common", "vehicle_sim", "offboard", "gcs"},
}
MAX_MODULES_PER_FOLDER = 20


def module_files(root: Path, packages: Iterable[str]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under the packages."""
    mods: dict[str, Path] = {}
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            mods[".".join(parts)] = f
    return mods


def imports_of(name: str, path: Path, mods: Mapping[str, Path]) -> set[str]:
    """The project modules that ``name`` imports, anywhere in its file."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def add(target: str) -> None:
        while target and target not in mods:  # a name inside a module: that module
            target = target.rpartition(".")[0]
        if target and target != name:
            found.add(target)

    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*up, *([node.module] if node.module else [])])
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                add(sub if sub in mods else base)
    return found


def import_graph(root: Path, packages: Iterable[str]) -> dict[str, set[str]]:
    mods = module_files(root, packages)
    return {name: imports_of(name, path, mods) for name, path in mods.items()}


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, it = work[-1]
            nxt = next((w for w in it if w in graph), None)
            if nxt is not None:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == node:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def room_of(module: str) -> str:
    """The room a module lives in: ``pkg.sub`` for a module of a subpackage, else itself
    (a module at the top of a package is a room of its own)."""
    parts = module.split(".")
    return ".".join(parts[:2])


def room_graph(graph: Mapping[str, Iterable[str]]) -> dict[str, set[str]]:
    rooms: dict[str, set[str]] = {room_of(m): set() for m in graph}
    for m, targets in graph.items():
        for t in targets:
            if room_of(t) != room_of(m):
                rooms[room_of(m)].add(room_of(t))
    return rooms


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph(ROOT, PACKAGES)


def test_the_checker_finds_a_cycle_made_on_purpose(tmp_path):
    pkg = tmp_path / "toy"
    (pkg / "inner").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "inner" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from toy.inner import b\n")
    (pkg / "inner" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from toy.c import C\n"
    )
    (pkg / "c.py").write_text("def f():\n    from . import a\n")
    g = import_graph(tmp_path, ["toy"])
    assert g["toy.a"] == {"toy.inner.b"}
    assert cycles(g) == [["toy.a", "toy.c", "toy.inner.b"]]
    (pkg / "c.py").write_text("X = 1\n")
    assert cycles(import_graph(tmp_path, ["toy"])) == []


def test_no_module_imports_itself_back(graph):
    assert cycles(graph) == []


def test_no_room_imports_itself_back(graph):
    assert cycles(room_graph(graph)) == []


def test_the_layers_are_one_way(graph):
    wrong = sorted(
        f"{m} -> {t}"
        for m, targets in graph.items()
        for t in targets
        if t.split(".")[0] not in ALLOWED[m.split(".")[0]]
    )
    assert wrong == []


def test_every_room_is_small_and_says_what_it_holds():
    for pkg in PACKAGES:
        for init in (ROOT / pkg).rglob("__init__.py"):
            folder = init.parent
            n = len(list(folder.glob("*.py")))
            assert n <= MAX_MODULES_PER_FOLDER + 1, f"{folder}: {n} modules"
            doc = ast.get_docstring(ast.parse(init.read_text())) or ""
            stems = {f.stem for f in folder.glob("*.py")} | {d.name for d in folder.iterdir()}
            named = {w.strip("`:.,()*~").rsplit(".", 1)[-1] for w in doc.split()} & stems
            assert named, f"{init}: its docstring names none of the room's modules"
