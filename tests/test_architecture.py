"""The package's shape, checked from its own source: the layers of
docs/explanation/architecture.md, no import that points back up (which also rules out every
import cycle), and no function too long to read as one page.

Imports are read with `ast`, the deferred ones inside functions included: an import made
late to save start-up time is still a dependency.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "rodphase"

# Bottom to top: a module may import only modules of lower rows (or of its own row, where
# the row names an order: within a row, only modules to its left). The order is the data
# flow of ../shared/DESIGN.md (config -> scene -> kernel -> result -> store -> classify ->
# plot) read as dependencies: the rod engine knows nothing of configs, the store nothing of
# sweeps, the CLI and the Python API sit on top of everything.
LAYERS = [
    # leaves: units and the run's result record, shared by everything
    ["_version", "units", "result", "resample", "export"],
    # the rod engine: compiled laws, the time-stepping kernel, its driver and the static side
    ["rod._jit", "rod.rotation", "rod.contact", "rod.neo_hookean", "rod.kernel",
     "rod.model", "rod.static", "rod.simulate", "rod", "theory", "rod.onset"],
    # the config's words, validated (it reads only units): a table reads a store's config
    ["config"],
    # reading a finished shape: link/twist/writhe, alignment, labels, tables of labels
    ["topology", "analysis", "classify", "tabulate"],
    # from the config to a scene the engine can run
    ["scenes"],
    # the store, and starting a run from a stored state
    ["store", "restart"],
    # running: one scene, one path of the map, a sweep of many, the lines traced by runs
    ["runner", "paths", "sweep", "boundaries"],
    # drawing
    ["plot"],
    # what users call: the Python API, the helpers of studies/, the CLI, the package
    ["api", "studytools", "cli", ""],
]
ORDER = {name: (row, col) for row, names in enumerate(LAYERS) for col, name in enumerate(names)}
LONGEST_FUNCTION = 150  # lines: about one printed page
# known to be longer, and why: kernel.advance writes its step loop out, because numba counts
# references around every inlined helper that binds arrays and each block of the loop made a
# helper cost 6-18 % per step (rod/kernel.py's module docstring, issue #27). The test fails
# once one of them is short, so that this list only shrinks
LONG_TODAY = {"rod.kernel.advance"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str) -> set[str]:
    """The package's modules that module `name` imports (at the top or inside a function)."""
    path = MODULES[name]
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    package = [p for p in package if p]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").startswith("rodphase"):
                target = node.module[len("rodphase."):] if "." in node.module else ""
            else:
                continue
            for alias in node.names:
                module = f"{target}.{alias.name}".lstrip(".")
                found.add(module if module in MODULES else target)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("rodphase"):
                    found.add(alias.name[len("rodphase."):] if "." in alias.name else "")
    found.discard(name)
    return found


def test_every_module_has_a_layer():
    assert sorted(set(MODULES) - set(ORDER)) == [], "add the new module to LAYERS"
    assert sorted(set(ORDER) - set(MODULES)) == [], "a module in LAYERS no longer exists"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_point_down(name):
    up = sorted(target for target in _imports(name) if ORDER[target] >= ORDER[name])
    assert up == [], f"{name or 'rodphase'} imports {up}, which are not below it in LAYERS"


def test_the_checker_sees_imports():
    # the rules above are only as good as the import reader: it must see the deferred,
    # relative and package-level imports that it is meant to forbid
    assert {"config", "runner", "scenes", "store", "sweep"} <= _imports("cli")
    assert "api" in _imports("")  # the lazy import in the package's __getattr__
    assert "rod.kernel" in _imports("rod.model") and "units" in _imports("rod.model")


def test_no_function_is_longer_than_a_page():
    long = {}
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > LONGEST_FUNCTION:
                    long[f"{name}.{node.name}"] = lines
    assert set(long) == LONG_TODAY, long
