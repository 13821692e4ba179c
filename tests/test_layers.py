"""The package's import graph, read from the source with `ast` (every import, inside functions too): layers
point one way and no two modules import each other, directly or round a loop (docs/architecture.md).

    errors <- model <- task <- render <- backends <- envs, study, io <- train <- cli <- the package itself

A module imports its own layer or those below it, never one above. Packages on one layer (envs, study, io)
may import each other; the cycle check keeps their modules from going round in a loop.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "mjx_pusht"

# Lowest first. A name is a subpackage or a top-level module of mjx_pusht; "" is the package's own
# __init__ (the public API, which imports from everywhere and is imported by nothing inside).
LAYERS = (
    ("errors", "validate", "boundary"),  # the one error base; the validation layer and the declared rules every entry
    # point checks its inputs through
    ("model",),
    ("task", "scenario"),  # the scenario is what to simulate: a scene, a reset, a controller, an episode
    ("api",),  # the model's and the task's helpers the package exports, their arguments checked at the door
    ("render",),
    ("backends",),
    ("envs", "study", "io"),
    ("train",),
    ("cli", "__main__"),
    ("",),
)

def modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every .py under `root` (a package's __init__ named as the package)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        name = ".".join((root.name, *path.relative_to(root).with_suffix("").parts))
        out[name.removesuffix(".__init__")] = path
    return out


def import_graph(root: Path) -> dict[str, dict[str, int]]:
    """Module -> {module of the package it imports: the first line that does}. `from a.b import c` counts as
    importing a.b.c when that is a module, else a.b; a module's imports of its own subpackages' __init__ (its
    parents) are not edges, but an import of the package itself (`from mjx_pusht import X`) is."""
    mods = modules(root)
    graph: dict[str, dict[str, int]] = {m: {} for m in mods}
    for m, path in mods.items():
        package = m if path.name == "__init__.py" else m.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: from .x import y, from .. import z
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                names = [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for name in names:
                while name and name not in mods:  # the longest prefix that is a module of ours
                    name = name.rpartition(".")[0]
                if name and name != m and (name == root.name or not m.startswith(name + ".")):
                    graph[m].setdefault(name, node.lineno)
    return graph


def unit(module: str) -> str:
    """The name LAYERS places a module by: its subpackage, or its own name at the top ("" for the package)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer_of(module: str, layers=LAYERS) -> int | None:
    for i, names in enumerate(layers):
        if unit(module) in names:
            return i
    return None


def upward_imports(graph, layers=LAYERS) -> list[str]:
    """One line for each import of a layer above the importer's."""
    bad = []
    for m, imported in sorted(graph.items()):
        for n, line in sorted(imported.items()):
            a, b = layer_of(m, layers), layer_of(n, layers)
            if a is not None and b is not None and b > a:
                bad.append(f"{m} (line {line}, layer {a}: {'/'.join(layers[a]) or 'mjx_pusht'}) imports {n} "
                           f"(layer {b}: {'/'.join(layers[b]) or 'mjx_pusht'}), a layer above it")
    return bad


def cycles(graph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def cycle_edges(graph, comp: list[str]) -> set[tuple[str, str]]:
    return {(m, n) for m in comp for n in graph[m] if n in comp}


def describe_cycle(graph, comp: list[str]) -> str:
    return "cycle: " + "; ".join(f"{m} -> {n} (line {graph[m][n]})" for m, n in sorted(cycle_edges(graph, comp)))


@pytest.fixture(scope="module")
def graph():
    return import_graph(ROOT)


def test_every_package_and_top_level_module_has_a_layer(graph):
    unplaced = sorted({unit(m) for m in graph if layer_of(m) is None})
    assert not unplaced, f"place {unplaced} in tests/test_layers.py LAYERS (and docs/architecture.md)"


def test_layers_point_one_way(graph):
    bad = upward_imports(graph)
    assert not bad, ("imports that point up the layers (" + " <- ".join("/".join(n) or "mjx_pusht" for n in LAYERS)
                     + "):\n" + "\n".join(bad))


def test_no_module_imports_itself_round_a_loop(graph):
    comps = cycles(graph)
    assert not comps, "import cycles between modules:\n" + "\n".join(describe_cycle(graph, c) for c in comps)


def test_the_checks_find_a_cycle_and_an_upward_import(tmp_path):
    """The checks themselves, on a made-up package: a cycle inside a function's import, a relative import up."""
    pkg = tmp_path / "mjx_pusht"
    for path, text in {
        "__init__.py": "",
        "task/__init__.py": "",
        "task/a.py": "def f():\n    from mjx_pusht.task import b\n",
        "task/b.py": "from . import c\n",
        "task/c.py": "import mjx_pusht.task.a\nfrom ..backends.base import X\n",
        "backends/__init__.py": "",
        "backends/base.py": "X = 1\n",
        "backends/cpu.py": "from mjx_pusht import api\nfrom . import base\n",
    }.items():
        (pkg / path).parent.mkdir(parents=True, exist_ok=True)
        (pkg / path).write_text(text)
    g = import_graph(pkg)
    assert cycles(g) == [["mjx_pusht.task.a", "mjx_pusht.task.b", "mjx_pusht.task.c"]]
    up = upward_imports(g, (("task",), ("backends",), ("",)))
    assert len(up) == 2, up
    assert up[0].startswith("mjx_pusht.backends.cpu (line 1, layer 1: backends) imports mjx_pusht (layer 2")
    assert up[1].startswith("mjx_pusht.task.c (line 2, layer 0: task) imports mjx_pusht.backends.base (layer 1")
