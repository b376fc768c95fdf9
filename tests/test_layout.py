"""The code's layout shows the pipeline: layers import only downwards, no import circle, small modules."""
from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO

# the pipeline, lowest layer first; a module may import its own layer or any lower one
LAYERS = (
    ("sasmi.errors",),
    ("sasmi.limits",),
    ("sasmi.images", "sasmi.preprocess", "sasmi.labels", "sasmi.masks"),
    ("sasmi.scene", "sasmi.presets", "sasmi.weights"),  # the data packages: presets and shipped weights
    ("sasmi.render",),
    ("sasmi.renderset",),
    ("sasmi.chips",),
    ("sasmi.gan",),
    ("sasmi.eval",),
    ("sasmi.realism",),
    ("sasmi.atr",),
    ("sasmi.cli",),
)
FACADE = ("sasmi", "sasmi.__main__")  # the package's front door: `from sasmi import render, __version__`
MAX_LINES = 350
MAX_TOP_MODULES = 12


def _modules() -> dict[str, Path]:
    found = {}
    for root, package in ((REPO / "sasmi", "sasmi"), (REPO / "gan", "sasmi.gan")):
        for path in root.rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join([package, *parts])] = path
    return found


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Every sasmi module `name` imports, at the top or inside a function."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            base = node.module
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        out |= {t for t in targets if t.startswith("sasmi") and t != name}
    return out


def _layer(module: str) -> int | None:
    for rank, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    return None


def test_every_module_has_a_layer_and_imports_only_downwards():
    modules = _modules()
    unplaced = [m for m in modules if m not in FACADE and _layer(m) is None]
    assert not unplaced, f"modules in no layer of LAYERS: {unplaced}"
    upward = [f"{m} -> {t}" for m, path in modules.items() if m not in FACADE
              for t in _imports(m, path, modules) if t not in FACADE and _layer(t) > _layer(m)]
    assert not upward, upward


def test_no_import_circle():
    modules = _modules()
    graph = {m: {t for t in _imports(m, p, modules) if t in modules and t not in FACADE} for m, p in modules.items()}
    circles, state = [], {}

    def visit(m, stack):
        state[m] = "open"
        for t in sorted(graph[m]):
            if state.get(t) == "open":
                circles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t, stack + [t])
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not circles, circles


def test_modules_are_small_and_the_top_level_is_short():
    modules = _modules()
    long = {m: n for m, p in modules.items() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, long
    top = sorted(p.name for p in (REPO / "sasmi").glob("*.py"))
    assert len(top) <= MAX_TOP_MODULES, top
