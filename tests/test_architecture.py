"""The package's structure, held to docs/ARCHITECTURE.md: layers point down only (imports inside
functions included), no import circles, no module over 600 lines, no public name that shadows a
submodule, and cvxpy loaded only by the routes that build a cvxpy problem."""

from __future__ import annotations

import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import lago_cvx

PKG = Path(lago_cvx.__file__).resolve().parent

#: The layers of docs/ARCHITECTURE.md, bottom first. A module may import from its own layer or below.
LAYERS = [
    ["_version", "errors", "progress", "solvers", "cvxpy_names", "routes", "conventions", "optimality", "reports",
     "stacks"],
    ["sparse"],
    ["posegraph_base", "posegraph", "so3", "posegraph3d"],
    ["io", "graph", "metrics", "metrics3d", "synthetic", "datasets"],
    ["uncertainty", "rounding"],
    ["regularization"],
    ["phases", "positions", "space"],
    ["result"],
    ["variants"],
    ["pipeline"],
    ["refinement", "refine_variants"],
    ["certification"],
    ["experiments", "plotting", "peers", "theorem1", "course_figures", "course", "course_sliders", "section_v",
     "exercises"],
    ["cli", "__main__", "__init__"],
]
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}
MAX_LINES = 600


def _modules() -> dict[str, Path]:
    """Dotted name inside the package (``regularization.chordal``) → file."""
    out = {}
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__" and len(parts) > 1:
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path) -> set[str]:
    """Package-internal modules imported by ``name`` (anywhere in the file), as dotted names."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    if name == "__init__":
        base = []
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parent = base[:len(base) - (node.level - 1)] if node.level > 1 else base
                mod = ".".join(parent + ([node.module] if node.module else []))
            elif node.module and node.module.startswith("lago_cvx"):
                mod = node.module[len("lago_cvx"):].lstrip(".")
            else:
                continue
            for alias in node.names:  # `from . import phases` names a submodule
                sub = f"{mod}.{alias.name}" if mod else alias.name
                found.add(sub if sub in MODULES else mod)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("lago_cvx."):
                    found.add(alias.name[len("lago_cvx."):])
    return {m for m in found if m and m != name}


MODULES = _modules()


def _layer(module: str) -> int:
    return LAYER[module.split(".")[0]]


def test_every_module_has_a_layer():
    missing = sorted({m.split(".")[0] for m in MODULES} - set(LAYER))
    assert not missing, f"modules without a layer in docs/ARCHITECTURE.md: {missing}"


def test_imports_point_down_only():
    upward = []
    for name, path in MODULES.items():
        for target in _imports(name, path):
            top = target.split(".")[0]
            if top in LAYER and _layer(target) > _layer(name):
                upward.append(f"{name} (layer {_layer(name)}) imports {target} (layer {_layer(target)})")
    assert not upward, "imports that run up a layer:\n" + "\n".join(upward)


#: The engine's one door: outside ``lago_cvx/sparse/`` only the package itself may be imported.
ENGINE = "sparse"


def test_engine_is_one_folder_behind_one_door():
    engine_files = {m for m in MODULES if m.split(".")[0] == ENGINE}
    assert engine_files and all((PKG / ENGINE) in MODULES[m].parents or m == ENGINE for m in engine_files)
    private = []
    for name, path in MODULES.items():
        if name.split(".")[0] == ENGINE:
            continue
        private += [f"{name} imports {t}" for t in _imports(name, path) if t.startswith(ENGINE + ".")]
    assert not private, "the engine's private modules imported from outside:\n" + "\n".join(private)
    # and the engine knows nothing of the mathematics above it
    upward = [f"{name} imports {t}" for name, path in MODULES.items() if name.split(".")[0] == ENGINE
              for t in _imports(name, path) if not t.startswith(ENGINE) and _layer(t) >= LAYER[ENGINE]]
    assert not upward, "\n".join(upward)


#: Words of an engine's plumbing that the mathematics never needs (threads, C pointers, memory mapping,
#: the engine's own size thresholds).
PLUMBING = ("threading", "ctypes", "mmap", "concurrent.futures", "COMPILED_MIN", "ENGINE_MIN", "numba", "threadpoolctl",
            "WIDE_COMPILED_MIN")
MATHEMATICS = ("uncertainty", "rounding", "regularization", "phases", "positions", "result", "variants",
               "pipeline", "refinement", "certification", "theorem1", "graph", "posegraph", "metrics", "metrics3d", "space",
               "so3", "posegraph3d")


def test_the_mathematics_holds_no_engine_plumbing():
    found = []
    for name, path in MODULES.items():
        if name.split(".")[0] not in MATHEMATICS:
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] + ([node.module] if getattr(node, "module", None) else [])
                found += [f"{name}: imports {n}" for n in names if n and n.split(".")[0] in PLUMBING]
            elif isinstance(node, ast.Name) and node.id in PLUMBING:
                found.append(f"{name}: uses {node.id}")
    assert not found, "engine plumbing in the mathematics:\n" + "\n".join(sorted(set(found)))


def test_no_import_circles():
    graph = {name: {t for t in _imports(name, path) if t in MODULES} for name, path in MODULES.items()}
    # a package's __init__ re-exporting its own submodules is not a circle of the design; the edge
    # submodule → package __init__ would be
    state, stack, circles = {}, [], []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in graph[v]:
            if state.get(w) == 1:
                circles.append(stack[stack.index(w):] + [w])
            elif w not in state:
                visit(w)
        stack.pop()
        state[v] = 2

    for v in graph:
        if v not in state:
            visit(v)
    assert not circles, "import circles: " + "; ".join(" → ".join(c) for c in circles)


def test_no_module_exceeds_the_size_limit():
    big = {str(p.relative_to(PKG)): n for p in PKG.rglob("*.py")
           if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"


def test_no_public_name_shadows_a_submodule():
    submodules = {m.name for m in pkgutil.iter_modules([str(PKG)])}
    assert not submodules & set(lago_cvx.__all__), submodules & set(lago_cvx.__all__)
    for name in lago_cvx.__all__:  # every public name resolves
        assert getattr(lago_cvx, name) is not None


def _loaded_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys; print(' '.join(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True).stdout.split()
    return set(out)


@pytest.mark.parametrize("code", [
    "import lago_cvx",
    "import lago_cvx as lc; lc.lago(lc.manhattan_world(50, seed=0).graph)",
    "from lago_cvx.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass",
    "import os, tempfile\nfrom lago_cvx.cli import main\nd = tempfile.mkdtemp()\n"
    "main(['generate', '--poses', '50', '-o', os.path.join(d, 'w.g2o')])\n"
    "main(['solve', os.path.join(d, 'w.g2o'), '-o', os.path.join(d, 'out.g2o'), '--json'])",
], ids=["import", "lago", "cli-help", "cli-solve"])
def test_closed_form_route_never_imports_cvxpy(code):
    assert "cvxpy" not in _loaded_after(code)


def test_cvxpy_route_imports_it():
    assert "cvxpy" in _loaded_after("import lago_cvx as lc; lc.lago(lc.manhattan_world(50, seed=0).graph, "
                                    "method='cvxpy')")


def test_the_pipeline_reads_as_section_iv():
    """``lago()``'s body — tree, regularization, phases 1–3, positions, each a call — stays at most 60 lines
    after its docstring: scheduling and prefetching belong to the engine."""
    tree = ast.parse((PKG / "pipeline.py").read_text())
    lago = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "lago")
    body = lago.end_lineno - lago.body[0].end_lineno
    assert body <= 60, f"lago()'s body is {body} lines"
