"""No import cycles: the strongly connected components of the module import graph are
single modules.

The graph has a node per module of ``onboard/``, ``drivers/``, ``sitl/`` and
``validation/`` (``drivers`` and ``sitl`` under the names they are installed as) and an
edge for every import of one of them by another, read with :mod:`ast` as the layering
test reads them (:mod:`tests.helpers.imports`): lazy imports inside functions and
``importlib.import_module`` of a string literal count, a package's ``__init__`` is a node
like any module (a package that imports its submodules while they import it is a
cycle). Two graphs are checked: the run-time one, without the imports under
``if TYPE_CHECKING:``; and the design one with them, in which two modules that name each
other's types for the type checker are a cycle too.

Two modules in one cycle cannot be read, tested or changed one without the other; the
way out is the piece both need, moved where it belongs.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import pytest

from tests.helpers.imports import REPO, imports_of, module_name

TOP_LEVEL = ("onboard", "drivers", "sitl", "validation")
"""The folders whose modules are nodes of the graph."""
OURS = {"onboard", "validation"}
"""Top-level names of the imports that are edges (``drivers`` and ``sitl`` are imported
as ``onboard.drivers`` and ``onboard.sitl``)."""

Graph = dict[str, dict[str, list[int]]]
"""Module -> {imported module: the lines of its imports}."""


def sources() -> dict[str, Path]:
    """Every module of the repository's packages, by name."""
    return {module_name(p): p for top in TOP_LEVEL for p in sorted((REPO / top).rglob("*.py"))}


def import_graph(modules: dict[str, Path], *, type_hints: bool) -> Graph:
    """The edges between ``modules`` (imports of anything else are left out)."""
    graph: Graph = {m: {} for m in modules}
    for m, path in modules.items():
        for line, target in imports_of(path, m, ours=OURS, type_hints=type_hints):
            if target in modules and target != m:
                graph[m].setdefault(target, []).append(line)
    return graph


def reachable(graph: Graph, start: str) -> set[str]:
    """The modules ``start`` imports, directly or through others."""
    seen: set[str] = set()
    todo = deque(graph[start])
    while todo:
        m = todo.popleft()
        if m not in seen:
            seen.add(m)
            todo.extend(graph[m])
    return seen


def strongly_connected_components(graph: Graph) -> list[set[str]]:
    """The classes of modules that reach each other (a module in no cycle is alone)."""
    reach = {m: reachable(graph, m) for m in graph}
    components: list[set[str]] = []
    placed: set[str] = set()
    for m in sorted(graph):
        if m not in placed:
            component = {m} | {other for other in reach[m] if m in reach[other]}
            placed |= component
            components.append(component)
    return components


def cycles(graph: Graph) -> list[str]:
    """Every component of more than one module, with the imports that tie it."""
    out = []
    for component in strongly_connected_components(graph):
        if len(component) > 1:
            edges = [f"{a} -> {b} (line {', '.join(map(str, sorted(set(graph[a][b]))))})"
                     for a in sorted(component) for b in sorted(graph[a]) if b in component]
            out.append(f"{sorted(component)}: " + "; ".join(edges))
    return out


@pytest.mark.parametrize("type_hints", [False, True], ids=["run-time", "with-type-hints"])
def test_no_module_imports_itself_through_others(type_hints: bool) -> None:
    found = cycles(import_graph(sources(), type_hints=type_hints))
    assert not found, "import cycles:\n" + "\n".join(found)


def _probe(tmp_path: Path, files: dict[str, str]) -> dict[str, Path]:
    """Modules ``onboard.probe.<name>`` (``__init__``: the package) with the given text."""
    out = {}
    for name, text in files.items():
        path = tmp_path / f"{name}.py"
        path.write_text(text)
        out["onboard.probe" if name == "__init__" else f"onboard.probe.{name}"] = path
    return out


def test_the_cycle_check_sees_a_cycle_through_a_lazy_import(tmp_path: Path) -> None:
    """A negative control: a -> b -> c -> a, the last edge inside a function."""
    modules = _probe(tmp_path, {
        "a": "from onboard.probe.b import B\n",
        "b": "import onboard.probe.c\n",
        "c": "def f():\n    from onboard.probe.a import A\n    return A\n",
        "d": "from onboard.probe.a import A\n",
    })
    graph = import_graph(modules, type_hints=False)
    assert {frozenset(c) for c in strongly_connected_components(graph) if len(c) > 1} == {
        frozenset({"onboard.probe.a", "onboard.probe.b", "onboard.probe.c"})}
    (report,) = cycles(graph)
    assert "onboard.probe.c -> onboard.probe.a (line 2)" in report


def test_the_cycle_check_sees_a_package_and_its_submodule(tmp_path: Path) -> None:
    """A negative control: a package's factory imports a submodule that imports the
    package's shared definitions."""
    modules = _probe(tmp_path, {
        "__init__": "def make():\n    from onboard.probe.impl import Impl\n    return Impl()\n",
        "impl": "from onboard.probe import Params\n",
    })
    assert cycles(import_graph(modules, type_hints=False))


def test_type_hints_make_a_cycle_only_in_the_design_graph(tmp_path: Path) -> None:
    """A negative control: a back edge under ``if TYPE_CHECKING:`` is no run-time cycle,
    but a cycle of the design graph."""
    modules = _probe(tmp_path, {
        "a": "from onboard.probe.b import B\n",
        "b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
             "    from onboard.probe.a import A\n",
    })
    assert not cycles(import_graph(modules, type_hints=False))
    assert cycles(import_graph(modules, type_hints=True))
