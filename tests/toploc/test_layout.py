"""The shape of the code: imports point down the floors, no two modules import each other, and
the cores load no I/O libraries.

Floors, from the ground up (docs/architecture.md): ``homing`` and the pure records
(``mapdb.records``); ``mapdb``; ``localizer``; ``robot``; the shell ``toploc``. A module may
import its own floor and the floors below it, never one above. Within a floor, the modules'
import graph has no cycle: an import inside a function counts (it is a dependency all the same,
only a later one), an import under ``if TYPE_CHECKING:`` does not (it never runs).

The thesis reproduction (``homing.thesis``) stands on the ground floor beside the homing
runtime, but only the shell imports it: the runtime (the rest of ``homing``, and ``mapdb``,
``localizer``, ``robot``) never does.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import networkx as nx
import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("homing", "mapdb", "localizer", "robot", "toploc")
FLOOR = {"homing": 0, "mapdb.records": 0, "mapdb": 1, "localizer": 2, "robot": 3, "toploc": 4}
IO_LIBRARIES = ("sqlite3", "sqlite_utils", "zenoh", "serial", "click", "tqdm")
REPRODUCTION = "homing.thesis"


def floor_of(module: str) -> int | None:
    """The floor of a dotted module name of toploc's packages (``None`` for other libraries)."""
    parts = module.split(".")
    for length in range(len(parts), 0, -1):
        floor = FLOOR.get(".".join(parts[:length]))
        if floor is not None:
            return floor
    return None


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def is_type_checking(test: ast.expr) -> bool:
    """Whether an ``if`` test is ``TYPE_CHECKING`` (or ``typing.TYPE_CHECKING``)."""
    if isinstance(test, ast.Name):
        return test.id == "TYPE_CHECKING"
    return isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"


def import_statements(tree: ast.AST, runtime_only: bool) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement in ``tree``, also inside functions and classes; with
    ``runtime_only``, none in the body of an ``if TYPE_CHECKING:`` (its ``else`` still counts)."""
    pending: list[ast.AST] = [tree]
    while pending:
        node = pending.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        if runtime_only and isinstance(node, ast.If) and is_type_checking(node.test):
            pending += node.orelse
        else:
            pending += ast.iter_child_nodes(node)


def imported_modules(path: Path, runtime_only: bool = False) -> list[tuple[int, str]]:
    """``(line, module)`` of every import in ``path``, relative imports resolved, by line;
    ``runtime_only``: not those under ``if TYPE_CHECKING:``."""
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = []
    for node in import_statements(ast.parse(path.read_text(), str(path)), runtime_only):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        else:
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return sorted(found)


def upward_imports(paths: list[Path]) -> list[str]:
    """Every import of a module on a higher floor than the importing one, as text."""
    upward = []
    for path in paths:
        here = floor_of(module_name(path))
        assert here is not None, path
        for line, module in imported_modules(path):
            there = floor_of(module)
            if there is not None and there > here:
                upward.append(f"{path.relative_to(REPO)}:{line} imports {module}")
    return upward


def source_files() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (REPO / package).rglob("*.py"))


def is_within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def reproduction_imports(paths: list[Path]) -> list[str]:
    """Every import of the thesis reproduction by a module outside it and outside the shell."""
    found = []
    for path in paths:
        here = module_name(path)
        if is_within(here, REPRODUCTION) or is_within(here, "toploc"):
            continue
        for line, module in imported_modules(path):
            if is_within(module, REPRODUCTION):
                found.append(f"{path.relative_to(REPO)}:{line} imports {module}")
    return found


def module_of(imported: str, modules: set[str]) -> str | None:
    """The module of ``modules`` an imported dotted name lives in (``toploc.bus.encode`` ->
    ``toploc.bus``), ``None`` for another library's."""
    parts = imported.split(".")
    for length in range(len(parts), 0, -1):
        if ".".join(parts[:length]) in modules:
            return ".".join(parts[:length])
    return None


def import_graph(paths: list[Path]) -> nx.DiGraph:
    """The modules of ``paths`` and an edge ``a -> b`` (attribute ``at``: ``file:line``) for
    each runtime import of ``b`` in ``a`` (a package is its ``__init__``)."""
    modules = {module_name(path): path for path in paths}
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for name, path in modules.items():
        for line, imported in imported_modules(path, runtime_only=True):
            target = module_of(imported, set(modules))
            if target is not None and target != name and not graph.has_edge(name, target):
                graph.add_edge(name, target, at=f"{path.relative_to(REPO)}:{line}")
    return graph


def import_cycles(paths: list[Path]) -> list[str]:
    """Each group of modules that import each other (a strongly connected component of the
    import graph), as text: one cycle through it, each import with its ``file:line``."""
    graph = import_graph(paths)
    found = []
    for component in nx.strongly_connected_components(graph):
        if len(component) > 1:
            cycle = nx.find_cycle(graph.subgraph(component))
            steps = [f"{a} -> {b} ({graph.edges[a, b]['at']})" for a, b in cycle]
            found.append(f"{len(component)} modules import each other: " + ", ".join(steps))
    return sorted(found)


def test_every_package_module_is_on_a_floor() -> None:
    assert all(floor_of(module_name(path)) is not None for path in source_files())


def test_imports_point_down_the_floors() -> None:
    assert upward_imports(source_files()) == []


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    bad = REPO / "localizer" / "_layout_probe.py"
    try:
        bad.write_text("from toploc.bus import encode\nfrom .belief import RoomBelief\n")
        assert upward_imports([bad]) == ["localizer/_layout_probe.py:1 imports toploc.bus.encode"]
    finally:
        bad.unlink()


def test_the_runtime_does_not_import_the_thesis_reproduction() -> None:
    assert reproduction_imports(source_files()) == []


def test_the_check_sees_the_runtime_import_the_reproduction() -> None:
    bad = REPO / "homing" / "_layout_probe.py"
    try:
        bad.write_text(
            "from homing.alv import HomingError\n"
            "def f():\n"
            "    from .thesis.simulation import simulate_runs\n"
        )
        assert reproduction_imports([bad]) == [
            "homing/_layout_probe.py:3 imports homing.thesis.simulation.simulate_runs"
        ]
    finally:
        bad.unlink()


def test_the_reproduction_and_the_shell_may_import_it() -> None:
    allowed = [REPO / "homing/thesis/controller.py", REPO / "toploc/commands/simulate.py"]
    assert all(any(is_within(m, REPRODUCTION) for _, m in imported_modules(p)) for p in allowed)
    assert reproduction_imports(allowed) == []


def test_no_two_modules_import_each_other() -> None:
    assert import_cycles(source_files()) == []


def probe_modules(texts: dict[str, str]) -> list[Path]:
    """Write ``localizer/<name>.py`` for each name and text (the caller unlinks them)."""
    paths = [REPO / "localizer" / f"{name}.py" for name in texts]
    for path, text in zip(paths, texts.values(), strict=True):
        path.write_text(text)
    return paths


def test_the_check_sees_an_import_cycle_through_a_function() -> None:
    paths = probe_modules(
        {
            "_cycle_probe_a": "from localizer._cycle_probe_b import helper\n",
            "_cycle_probe_b": "def helper():\n    from . import _cycle_probe_a\n",
        }
    )
    try:
        assert import_cycles(paths) == [
            "2 modules import each other: "
            "localizer._cycle_probe_a -> localizer._cycle_probe_b (localizer/_cycle_probe_a.py:1), "
            "localizer._cycle_probe_b -> localizer._cycle_probe_a (localizer/_cycle_probe_b.py:2)"
        ]
    finally:
        for path in paths:
            path.unlink()


def test_an_import_for_type_checking_only_makes_no_cycle() -> None:
    paths = probe_modules(
        {
            "_cycle_probe_a": "from localizer._cycle_probe_b import helper\n",
            "_cycle_probe_b": (
                "from typing import TYPE_CHECKING\n"
                "if TYPE_CHECKING:\n"
                "    from localizer._cycle_probe_a import helper\n"
            ),
        }
    )
    try:
        assert import_cycles(paths) == []
    finally:
        for path in paths:
            path.unlink()


def test_records_stand_on_the_ground_floor() -> None:
    assert floor_of("mapdb.records.Place") == 0
    assert floor_of("mapdb.database") == 1
    assert floor_of("numpy") is None


@pytest.mark.parametrize("package", ["homing", "localizer"])
def test_a_core_loads_no_io_library(package: str) -> None:
    # A fresh interpreter: the test process itself has loaded everything already.
    probe = (
        "import importlib, pkgutil, sys\n"
        f"import {package}\n"
        f"for info in pkgutil.walk_packages({package}.__path__, '{package}.'):\n"
        f"    importlib.import_module(info.name)\n"
        f"print(' '.join(sorted(n for n in {IO_LIBRARIES!r} if n in sys.modules)))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert done.stdout.split() == []
