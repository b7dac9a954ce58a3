"""The layout holds: one-way package dependencies, no import cycles, no studies or
``matplotlib.use`` in the library, and ``import pm_joint as pj`` reaches the entry points.

The import graph is read from the sources (every ``import`` statement, at module
level or inside functions), not from what a run happens to import.
"""

from __future__ import annotations

import ast
import importlib.util
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


def test_packages_depend_one_way(graph):
    for module, imported in graph.items():
        rank = PACKAGES.index(module.split(".")[0])
        later = sorted(m for m in imported if PACKAGES.index(m.split(".")[0]) > rank)
        assert not later, f"{module} imports {later} from a later package"


def test_no_import_cycles(graph):
    state: dict[str, str] = {}
    path: list[str] = []

    def visit(module: str) -> None:
        state[module] = "open"
        path.append(module)
        for other in sorted(graph[module]):
            if state.get(other) == "open":
                cycle = [*path[path.index(other) :], other]
                raise AssertionError(f"import cycle: {' -> '.join(cycle)}")
            if other not in state:
                visit(other)
        path.pop()
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module)


def test_no_library_module_imports_the_studies_or_sets_a_backend(graph):
    importers = sorted(
        m
        for m, imported in graph.items()
        if m.split(".")[0] != "studies" and any(i.split(".")[0] == "studies" for i in imported)
    )
    assert importers == [], f"library modules import the studies: {importers}"
    for module, path in _modules().items():
        assert "matplotlib.use(" not in path.read_text(encoding="utf-8"), module


#: What ``import pm_joint as pj`` must reach (the criticism adapter comes with its own module).
ENTRY_POINTS = (
    "BackboneAmplitude", "BackboneDensity", "forward_model", "build_model", "hierarchical_model",
    "sample", "continue_sampling", "save_posterior", "load_posterior", "JointModel",
    "BackboneSet", "Campaign", "extract_backbones", "identify", "Workspace", "report",
)  # fmt: skip


def test_import_pm_joint_is_cheap_and_reaches_the_entry_points():
    script = (
        "import sys\n"
        "import pm_joint as pj\n"
        "heavy = sorted(m for m in ('pymc', 'pytensor', 'torch', 'arviz') if m in sys.modules)\n"
        "assert not heavy, heavy\n"
        f"missing = [n for n in {ENTRY_POINTS!r} if not callable(getattr(pj, n))]\n"
        "assert not missing, missing\n"
        "assert set(pj.__all__) <= set(dir(pj))\n"
        # A submodule named like an entry point would shadow it once imported.
        "import pm_joint.pipeline\n"
        "assert pj.report.__module__ == 'pm_joint.report_folder', pj.report\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    import pm_joint as pj

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = pj.nope


@pytest.mark.skipif(
    importlib.util.find_spec("pm_joint.analysis.posterior") is None,
    reason="the posterior adapter of the criticism (pm_joint/analysis/posterior.py) is not here",
)
def test_pj_criticize_is_the_posterior_adapter():
    import pm_joint as pj

    assert pj.criticize.__module__ == "pm_joint.analysis.posterior"


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
