"""The packages' imports point one way: no import cycle in ``leg_env``, ``train`` or ``policies``, and no module that
only re-exports another's names.

The graph is read from the source (every ``import`` statement, those inside functions included, since a lazy
import closes a cycle as surely as an eager one), so the test needs no import to succeed and names the cycle it
finds. ``from package import name`` is an edge to the submodule ``package.name`` where there is one, else to the
package.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("leg_env", "train", "policies")


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


def _resolve(module: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph() -> dict[str, set[str]]:
    modules = _modules()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                source = _resolve(name, path, node)
                targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in modules else source for a in node.names]
            for target in targets:
                while target and target not in modules:  # a name inside a module: the module
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` (its modules in order), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_import_graph_finds_a_cycle_when_there_is_one():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_the_import_graph_is_read_from_the_source():
    graph = import_graph()
    assert "leg_env.physics.dynamics" in graph["leg_env.physics.integrate"]  # an eager import
    assert "leg_env.envs.single" in graph["leg_env.envs"]  # a lazy one, inside __getattr__


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    graph = import_graph()
    sub = {m: {t for t in ts if t.split(".")[0] in PACKAGES} for m, ts in graph.items()}
    cycle = _cycle(sub)
    assert cycle is None or not any(m.split(".")[0] == package for m in cycle), f"import cycle: {' -> '.join(cycle)}"


def test_the_physics_imports_no_gymnasium_and_no_task():
    """The physics is the bottom of the house: it imports the compiled core and argument checks, nothing above."""
    for name, path in _modules().items():
        if not name.startswith("leg_env.physics"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                source = _resolve(name, path, node) if isinstance(node, ast.ImportFrom) else node.names[0].name
                assert not source.startswith(("gymnasium", "leg_env.tasks", "leg_env.envs", "pygame", "torch")), (name, source)


def test_no_module_only_re_exports_another():
    """A module (a package's ``__init__.py`` aside) that holds nothing but imports and ``__all__`` is a shim."""
    shims = []
    for name, path in _modules().items():
        if path.name == "__init__.py":
            continue
        body = ast.parse(path.read_text()).body
        body = [n for n in body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]  # docstrings
        own = [n for n in body if not isinstance(n, (ast.Import, ast.ImportFrom))
               and not (isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets))]
        if body and not own:
            shims.append(name)
    assert not shims, f"modules that only re-export names: {shims}"
