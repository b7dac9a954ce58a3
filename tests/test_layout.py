"""The layout holds: one-way package dependencies, no import cycles, no studies or
``matplotlib.use`` in the library, and ``import pm_joint as pj`` reaches the entry points.

The import graph is read from the sources (every ``import`` statement, at module
level or inside functions), not from what a run happens to import.
"""

from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
#: The library's packages, each depending only on those before it, then the studies.
PACKAGES = ("identification", "surrogates", "pm_joint", "studies")


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    return modules


def _runtime_nodes(tree: ast.AST):
    """Every node of ``tree`` but those under ``if TYPE_CHECKING:``: an import made for
    annotations alone is never executed, so it makes no cycle at run time."""
    for child in ast.iter_child_nodes(tree):
        if isinstance(child, ast.If) and ast.unparse(child.test).endswith("TYPE_CHECKING"):
            for stmt in child.orelse:
                yield stmt
                yield from _runtime_nodes(stmt)
            continue
        yield child
        yield from _runtime_nodes(child)


def _imports(path: Path, known: dict[str, Path]) -> set[str]:
    """Library modules ``path`` imports (``from a import b`` may name a module ``a.b``)."""
    found = set()
    for node in _runtime_nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            submodules = {f"{node.module}.{alias.name}" for alias in node.names}
            found |= submodules
            # `from package import module` takes the module, not the package's own names
            # (Python imports the parent package first for every submodule anyway).
            if not submodules <= set(known):
                found.add(node.module)
    return {name for name in found if name in known}


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(path, modules) - {name} for name, path in modules.items()}


def later_imports(graph: dict[str, set[str]]) -> dict[str, list[str]]:
    """Modules that import from a package after their own in PACKAGES."""
    found = {}
    for module, imported in graph.items():
        rank = PACKAGES.index(module.split(".")[0])
        later = sorted(m for m in imported if PACKAGES.index(m.split(".")[0]) > rank)
        if later:
            found[module] = later
    return found


def import_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of the graph (its modules, the first repeated at the end), or None."""
    state: dict[str, str] = {}
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = "open"
        path.append(module)
        for other in sorted(graph.get(module, ())):
            if state.get(other) == "open":
                return [*path[path.index(other) :], other]
            if other not in state and (cycle := visit(other)):
                return cycle
        path.pop()
        state[module] = "done"
        return None

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)):
            return cycle
    return None


def test_packages_depend_one_way(graph):
    assert later_imports(graph) == {}


def test_no_import_cycles(graph):
    cycle = import_cycle(graph)
    assert cycle is None, f"import cycle: {' -> '.join(cycle)}"


def test_the_graph_checks_find_a_backward_import_and_a_cycle():
    """The checks above can fail: on a deliberately broken graph they do."""
    one_way = {"identification.a": {"identification.b"}, "identification.b": set(),
               "pm_joint.c": {"identification.a"}}  # fmt: skip
    assert later_imports(one_way) == {} and import_cycle(one_way) is None
    backward = {**one_way, "identification.b": {"pm_joint.c"}}
    assert later_imports(backward) == {"identification.b": ["pm_joint.c"]}
    assert import_cycle(backward) == [
        "identification.a", "identification.b", "pm_joint.c", "identification.a"
    ]  # fmt: skip


def test_no_library_module_imports_the_studies_or_sets_a_backend(graph):
    importers = sorted(
        m
        for m, imported in graph.items()
        if m.split(".")[0] != "studies" and any(i.split(".")[0] == "studies" for i in imported)
    )
    assert importers == [], f"library modules import the studies: {importers}"
    for module, path in _modules().items():
        assert "matplotlib.use(" not in path.read_text(encoding="utf-8"), module


#: What ``import pm_joint as pj`` must reach, and where each name lives (the criticism's
#: posterior adapter included: it is part of the front door, never optional).
ENTRY_POINTS = {
    "BackboneAmplitude": "pm_joint.distributions", "BackboneDensity": "pm_joint.distributions",
    "forward_model": "pm_joint.forward", "build_model": "pm_joint.inference",
    "hierarchical_model": "pm_joint.inference", "sample": "pm_joint.inference",
    "continue_sampling": "pm_joint.inference", "save_posterior": "pm_joint.inference",
    "load_posterior": "pm_joint.inference", "convergence_verdict": "pm_joint.analysis",
    "loo": "pm_joint.analysis", "criticize": "pm_joint.analysis.posterior",
    "report": "pm_joint.report_folder", "Workspace": "pm_joint.workspace",
    "JointModel": "identification.model", "BackboneSet": "identification.measurements.backbone",
    "extract_backbones": "identification.measurements.extraction",
    "Campaign": "identification.measurements.records", "identify": "identification.sindy",
}  # fmt: skip

#: Run in a fresh interpreter: the entry points a package's ``__all__`` names that do not
#: resolve, each name looked up itself (``dir`` may be built from ``__all__``, so
#: ``__all__ <= dir`` proves nothing), and the heavy modules its import pulled in.
_CHECK = """
import importlib, json, sys
package = importlib.import_module(sys.argv[1])
heavy = sorted(m for m in ("pymc", "pytensor", "torch", "arviz") if m in sys.modules)
broken = {}
for name in package.__all__:
    try:
        value = getattr(package, name)
    except Exception as error:
        broken[name] = f"{type(error).__name__}: {error}"
        continue
    if not callable(value):
        broken[name] = "not callable"
listed = set(package.__all__) <= set(dir(package))
print(json.dumps({"all": list(package.__all__), "heavy": heavy, "broken": broken,
                  "listed": listed}))
"""


def front_door(package: str, path: Path = ROOT) -> dict:
    """What ``import package`` offers: its ``__all__``, what resolves, what it costs."""
    done = subprocess.run(
        [sys.executable, "-c", _CHECK, package], cwd=path, capture_output=True, text=True,
        timeout=600, env={**os.environ, "PYTHONPATH": str(path)},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.splitlines()[-1])


def test_import_pm_joint_is_cheap_and_reaches_the_entry_points():
    door = front_door("pm_joint")
    assert door["heavy"] == []
    assert sorted(door["all"]) == sorted(ENTRY_POINTS)
    assert door["broken"] == {}
    import pm_joint as pj

    for name, module in ENTRY_POINTS.items():
        assert getattr(pj, name) is getattr(importlib.import_module(module), name), name
    # A submodule named like an entry point would shadow it once imported.
    import pm_joint.pipeline

    assert pj.report.__module__ == "pm_joint.report_folder", pj.report
    assert pj.criticize.__module__ == "pm_joint.analysis.posterior"
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = pj.nope


def test_the_front_door_check_fails_on_a_broken_package(tmp_path):
    """A package whose ``dir`` is built from its ``__all__`` (as pm_joint's) but whose
    lazy names point at a deleted module and a missing name: the check names both."""
    package = tmp_path / "broken_door"
    package.mkdir()
    (package / "__init__.py").write_text(
        "import importlib\n"
        "__all__ = ['gone', 'missing', 'fine']\n"
        "_LAZY = {'gone': 'broken_door.deleted_adapter', 'fine': 'broken_door.here'}\n"
        "def __getattr__(name):\n"
        "    if name in _LAZY:\n"
        "        return getattr(importlib.import_module(_LAZY[name]), name)\n"
        "    raise AttributeError(name)\n"
        "def __dir__():\n"
        "    return sorted([*globals(), *__all__])\n"
    )
    (package / "here.py").write_text("def fine():\n    pass\n")
    door = front_door("broken_door", tmp_path)
    assert door["listed"]  # what the check once rested on holds for the broken package too
    assert sorted(door["broken"]) == ["gone", "missing"]
    assert "ModuleNotFoundError" in door["broken"]["gone"]


def test_the_criticism_and_the_fits_do_not_need_pymc():
    """The criticism engine sits with the fits it uses; only pm_joint adapts posteriors to it."""
    for room in ("criticism", "fitting"):
        for path in (ROOT / "identification" / room).rglob("*.py"):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            names |= {
                n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module
            }
            heavy = sorted(n for n in names if n.split(".")[0] in ("pymc", "pytensor", "arviz"))
            assert not heavy, f"{path.relative_to(ROOT)} imports {heavy}"
