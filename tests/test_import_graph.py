"""Imports point down the layers: no module of jarena or jarena_agents imports, directly or through others, a
module that imports it back (counting imports inside functions and under TYPE_CHECKING too). Package
``__init__`` files, which gather their modules' names for users, are left out."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def module_graph(package: str) -> dict[str, set[str]]:
    """``module -> modules it imports`` over the non-``__init__`` modules of ``package``."""
    files = {".".join(f.relative_to(ROOT).with_suffix("").parts): f for f in (ROOT / package).rglob("*.py")
             if f.name != "__init__.py"}
    graph = {}
    for name, path in files.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                targets.update(t for t in [node.module] + [f"{node.module}.{a.name}" for a in node.names] if t in files)
            elif isinstance(node, ast.Import):
                targets.update(a.name for a in node.names if a.name in files)
        graph[name] = targets - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

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
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_the_checker_finds_a_circle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.parametrize("package", ["jarena", "jarena_agents"])
def test_no_module_imports_itself_back(package):
    assert cycles(module_graph(package)) == []


def test_importing_the_library_does_not_start_jax():
    """A multi-process run must call ``jax.distributed.initialize`` before JAX's backend starts: importing
    jarena, its agents and its command line may not start it (e.g. with a ``jnp`` constant at module level)."""
    import subprocess
    import sys

    code = ("import jax._src.xla_bridge as xb, jarena, jarena_agents, jarena.cli; "
            "assert not xb._backends, 'importing jarena started JAX backends'")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
