"""No catalogue effect is named by a string literal outside the effects package.

Every fact of an effect lives in its module of :mod:`identification.effects`;
the rest of the library reaches an effect through the :class:`Effect` record
(``effect.hysteretic``, ``effect.stuck_stiffness``, ``effect.term_text``, …)
and the name constants (``LINEAR_STIFFNESS``, ``VISCOUS_DAMPING``,
``HYSTERETIC``), never by spelling its name. The rig's scenario presets may name
effects (they build lab scenarios from them); docstrings may mention them in prose.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from identification.effects import CATALOGUE

ROOT = Path(__file__).parents[1]
PACKAGES = ("identification", "surrogates", "pm_joint")
#: Where effect names belong: the effects package and the rig's scenario presets.
ALLOWED = ("identification/effects/", "identification/rig/presets.py")
#: Catalogue names and ``name.shape`` parameter names.
EFFECT_NAMES = frozenset(CATALOGUE) | {
    f"{name}.{shape}" for name, effect in CATALOGUE.items() for shape in effect.shape
}


def named_effects(source: str) -> list[tuple[int, str]]:
    """``(line, literal)`` of every string constant equal to an effect name, docstrings aside."""
    tree = ast.parse(source)
    docstrings = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docstrings.add(id(first.value))
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
        and node.value in EFFECT_NAMES
    )


def library_modules() -> list[str]:
    """The three packages' modules that may not name effects (paths relative to the root)."""
    paths = [
        path.relative_to(ROOT).as_posix()
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
    ]
    return [p for p in paths if not p.startswith(ALLOWED)]


def test_the_checker_finds_a_literal_and_passes_a_docstring():
    source = (
        '"""Uses ``microslip`` in prose."""\n'
        "def f(model):\n"
        '    """The ``cubic_stiffness`` term."""\n'
        '    return model["microslip"], "microslip.k_t", f"{model}", "cubic"\n'
    )
    assert named_effects(source) == [(4, "microslip"), (4, "microslip.k_t")]


def test_the_packages_are_searched():
    modules = library_modules()
    assert "identification/model.py" in modules
    assert "identification/analytical/harmonic.py" in modules
    assert "pm_joint/analysis/posterior.py" in modules
    assert not any(m.startswith("identification/effects/") for m in modules)


@pytest.mark.parametrize("module", library_modules())
def test_no_effect_name_as_a_string_literal(module):
    found = named_effects((ROOT / module).read_text(encoding="utf-8"))
    assert not found, (
        f"{module} names catalogue effects by string literal (line, name): {found}; "
        "use the Effect record (identification.effects) instead"
    )
