"""The suite's split between the two venvs of ``make test``: what needs Stable-Baselines3 is chosen by folder and mark.

The RLlib venv has no Stable-Baselines3 and none of the other packages that only the ``[train]`` and ``[test]``
extras bring (the *training stack*: rl_zoo3, onnx, onnxruntime, rliable, ...). Its run ignores ``tests/sb3/``, whose
modules need the stack to be imported, and deselects the ``sb3`` mark (``-m "not sb3"``), which ``conftest.py`` puts
on every test of that folder and a test elsewhere carries itself. This module reads the sources (no import of the
stack) and checks, for every test module outside ``tests/sb3/``:

- its imports at module level reach no package of the stack, directly or through a project module that imports one
  when it is imported (such a module cannot even be collected there: it belongs in ``tests/sb3/``);
- each test whose code uses the stack carries the mark. Its code is its body, the module's helpers it calls and the
  fixtures it asks for (the module's and ``conftest.py``'s), with the names the module imports at its top. It uses
  the stack if it imports a package of the stack, or a project module that imports one, when imported or when
  called (``train.ppo``, ``train.curves``, ``leg_env.sb3``, ...), except the modules that load or save the runs of
  any framework and import SB3 only for an SB3 run (``OPTIONAL_USERS``).

What the sources cannot show (a shipped SB3 policy loaded by path through ``train.evaluate.load_policy``) fails in
the RLlib venv with ``ModuleNotFoundError``: a test there is never skipped.
"""

from __future__ import annotations

import ast
import importlib.metadata
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
SB3_FOLDER = TESTS / "sb3"
PROJECT_PACKAGES = ("leg_env", "train", "policies")
# project modules that import SB3 only to load or save an SB3 run (they serve RLlib runs and controllers alike)
OPTIONAL_USERS = {
    "train.policy_loading": "loads an SB3 or RLlib run, or a controller",
    "train.checkpoints": "saves and restores the checkpoints of either trainer",
}


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def training_stack() -> set[str]:
    """The import names of the packages that the ``[train]`` and ``[test]`` extras bring and ``[rllib]`` and
    ``[test-core]`` (the RLlib venv's) do not, read from the installed package's metadata."""
    from packaging.requirements import Requirement

    extras: dict[str, set[str]] = {}
    for line in importlib.metadata.requires("leg-env") or []:
        requirement = Requirement(line)
        extra = re.search(r'extra == "([^"]+)"', str(requirement.marker or ""))
        names = {f"[{e}]" for e in requirement.extras} if _canonical(requirement.name) == "leg-env" else {_canonical(requirement.name)}
        extras.setdefault(extra.group(1) if extra else "", set()).update(names)

    def closure(*names: str) -> set[str]:
        found, todo = set(), [f"[{n}]" for n in names]
        while todo:
            name = todo.pop()
            if name.startswith("["):
                todo += [n for n in extras.get(name[1:-1], ()) if n not in found]
            found.add(name)
        return {n for n in found if not n.startswith("[")}

    distributions = closure("train", "test") - closure("", "rllib", "test-core")
    installed: dict[str, set[str]] = {}
    for name, dists in importlib.metadata.packages_distributions().items():
        for dist in dists:
            if not name.startswith("_"):
                installed.setdefault(_canonical(dist), set()).add(name)
    # a distribution not installed here (the RLlib venv) is imported by its name with underscores, as all of them are
    imports = set().union(*(installed.get(d, {d.replace("-", "_")}) for d in distributions))
    assert "stable_baselines3" in imports, sorted(distributions)
    return imports


def _imported(node: ast.AST, package: str) -> list[str]:
    """The modules an import statement may import (``from m import n``: ``m`` and ``m.n``), relative ones resolved
    against ``package``."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if isinstance(node, ast.ImportFrom):
        base = node.module or ""
        if node.level:
            parent = package.split(".")[: len(package.split(".")) - node.level + 1]
            base = ".".join(parent + ([base] if base else []))
        return [base] + [f"{base}.{alias.name}" for alias in node.names]
    return []


def _imports_when_imported(tree: ast.Module, package: str) -> list[str]:
    """The imports a module runs when it is imported (not those inside its functions)."""
    found, todo = [], list(tree.body)
    while todo:
        node = todo.pop()
        found += _imported(node, package)
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            todo += list(ast.iter_child_nodes(node))
    return found


def _top(name: str) -> str:
    return name.split(".")[0]


def project_modules(root: Path = ROOT) -> dict[str, tuple[ast.Module, str]]:
    """Every module of the project's packages: its dotted name -> (syntax tree, its package)."""
    modules = {}
    for package in PROJECT_PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_init = parts[-1] == "__init__"
            name = ".".join(parts[:-1] if is_init else parts)
            modules[name] = (ast.parse(path.read_text(encoding="utf-8")), name if is_init else name.rpartition(".")[0])
    return modules


def stack_users(modules: dict[str, tuple[ast.Module, str]], stack: set[str]) -> tuple[set[str], set[str]]:
    """(the project modules that import the stack when imported, those that import it when imported or called,
    ``OPTIONAL_USERS`` left out), each through other project modules too."""

    def grow(imports_of) -> set[str]:
        users: set[str] = set()
        while True:
            more = {name for name, (tree, package) in modules.items() if name not in users and name not in OPTIONAL_USERS
                    and any(_top(m) in stack or m in users for m in imports_of(tree, package))}  # fmt: skip
            if not more:
                return users
            users |= more

    at_import = grow(_imports_when_imported)
    return at_import, grow(lambda tree, package: [m for node in ast.walk(tree) for m in _imported(node, package)])


def _bindings(tree: ast.Module) -> dict[str, list[str]]:
    """The names a test module's top-level imports bind -> the modules they may come from."""
    bound: dict[str, list[str]] = {}
    for node in tree.body:
        if isinstance(node, ast.Import):
            for alias in node.names:
                bound[alias.asname or _top(alias.name)] = [alias.name]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            for alias in node.names:
                bound[alias.asname or alias.name] = [node.module or "", f"{node.module}.{alias.name}"]
    return bound


def _is_sb3_mark(node: ast.AST) -> bool:
    node = node.func if isinstance(node, ast.Call) else node
    return isinstance(node, ast.Attribute) and node.attr == "sb3" and isinstance(node.value, ast.Attribute) and node.value.attr == "mark"


def unmarked_stack_tests(path: Path, stack: set[str], users: set[str], at_import: set[str]) -> list[str]:
    """What is wrong with the test module at ``path`` (outside ``tests/sb3/``): a module-level import of the stack,
    or a test that uses the stack without the ``sb3`` mark."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    conftest = ast.parse((TESTS / "conftest.py").read_text(encoding="utf-8"))

    def needs(modules: list[str]) -> list[str]:
        hits = {m for m in modules if _top(m) in stack or m in users}
        return sorted(m for m in hits if not any(m.startswith(f"{other}.") for other in hits))

    found = [f"{path.name}: imports {m} at module level, which needs the training stack: move it to tests/sb3/"
             for m in sorted({m for m in _imports_when_imported(tree, "") if _top(m) in stack or m in at_import})]  # fmt: skip
    module_marked = any(
        isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets)
        and any(_is_sb3_mark(n) for n in ast.walk(node.value))
        for node in tree.body
    )  # fmt: skip
    functions = {node.name: (node, conftest) for node in conftest.body if isinstance(node, ast.FunctionDef)}
    functions |= {node.name: (node, tree) for node in tree.body if isinstance(node, ast.FunctionDef)}
    bound = {tree: _bindings(tree), conftest: _bindings(conftest)}

    def used_modules(name: str, seen: set[str]) -> list[str]:
        if name in seen or name not in functions:
            return []
        seen.add(name)
        function, home = functions[name]
        modules = [m for node in ast.walk(function) for m in _imported(node, "")]
        for node in ast.walk(function):
            if isinstance(node, ast.Name):
                modules += bound[home].get(node.id, []) + used_modules(node.id, seen)
        for argument in function.args.args:  # the fixtures it asks for
            modules += used_modules(argument.arg, seen)
        return modules

    tests = [(name, function, []) for name, (function, home) in functions.items() if home is tree and name.startswith("test_")]
    for cls in (node for node in tree.body if isinstance(node, ast.ClassDef) and node.name.startswith("Test")):
        for method in (node for node in cls.body if isinstance(node, ast.FunctionDef) and node.name.startswith("test_")):
            functions[f"{cls.name}.{method.name}"] = (method, tree)
            tests.append((f"{cls.name}.{method.name}", method, cls.decorator_list))
    for name, function, outer_marks in tests:
        uses = needs(used_modules(name, set()))
        if uses and not module_marked and not any(_is_sb3_mark(d) for d in [*function.decorator_list, *outer_marks]):
            found.append(f"{path.name}::{name} uses {', '.join(uses)} without @pytest.mark.sb3")
    return found


@pytest.fixture(scope="module")
def stack_and_users():
    stack = training_stack()
    at_import, users = stack_users(project_modules(), stack)
    return stack, users, at_import


def test_the_training_stack_is_what_the_rllib_venv_lacks(stack_and_users):
    stack, users, at_import = stack_and_users
    assert {"stable_baselines3", "rl_zoo3", "onnx", "onnxruntime", "rliable"} <= stack
    assert not {"torch", "yaml", "scipy", "matplotlib", "gymnasium", "numpy", "pytest", "ray"} & stack
    assert {"leg_env.sb3", "train.chunked_ppo", "train.residual"} <= at_import
    assert {"train.ppo", "train.curves", "train.export", "train.falls"} <= users - at_import
    assert not {"leg_env", "leg_env.envs.vector", "train.evaluate", "train.episodes", "train.rllib", "policies.lqr"} & users
    direct = {name for name, (tree, package) in project_modules().items()
              if any(_top(m) in stack for node in ast.walk(tree) for m in _imported(node, package))}  # fmt: skip
    assert set(OPTIONAL_USERS) <= direct - at_import, "an entry of OPTIONAL_USERS no longer imports the stack only when called"


def test_every_test_that_needs_the_training_stack_is_in_its_folder_or_marked(stack_and_users):
    stack, users, at_import = stack_and_users
    found = []
    for path in sorted(TESTS.glob("test_*.py")):
        found += unmarked_stack_tests(path, stack, users, at_import)
    assert found == []


def test_the_check_finds_an_unmarked_test_and_a_module_level_import(stack_and_users, tmp_path):
    stack, users, at_import = stack_and_users
    module = tmp_path / "test_example.py"
    module.write_text(
        "import pytest\nfrom train.ppo import train\n\n"
        "def helper():\n    from leg_env.sb3 import make_sb3_vec_env\n\n"
        "@pytest.fixture\ndef trained(tmp_path):\n    return train(tmp_path)\n\n"
        "def test_plain():\n    assert True\n\n"
        "def test_by_helper():\n    helper()\n\n"
        "def test_by_fixture(trained):\n    pass\n\n"
        "def test_by_import():\n    from stable_baselines3 import PPO\n\n"
        "@pytest.mark.sb3\ndef test_marked():\n    from stable_baselines3 import PPO\n\n"
        "class TestGroup:\n    def test_in_a_class(self):\n        from train.curves import main\n"
    )
    assert unmarked_stack_tests(module, stack, users, at_import) == [
        "test_example.py::test_by_helper uses leg_env.sb3 without @pytest.mark.sb3",
        "test_example.py::test_by_fixture uses train.ppo without @pytest.mark.sb3",
        "test_example.py::test_by_import uses stable_baselines3 without @pytest.mark.sb3",
        "test_example.py::TestGroup.test_in_a_class uses train.curves without @pytest.mark.sb3",
    ]
    module.write_text("import pytest\nfrom train.residual import ResidualVecEnv\n\npytestmark = pytest.mark.sb3\n\ndef test_x():\n    ResidualVecEnv\n")
    assert unmarked_stack_tests(module, stack, users, at_import) == [
        "test_example.py: imports train.residual at module level, which needs the training stack: move it to tests/sb3/",
    ]


def test_conftest_marks_every_test_of_the_sb3_folder_and_no_other():
    from conftest import pytest_collection_modifyitems

    class Item:
        def __init__(self, path: Path):
            self.path, self.marks = path, []

        def add_marker(self, mark):
            self.marks.append(mark.name)

    inside, nested, outside = Item(SB3_FOLDER / "test_train.py"), Item(SB3_FOLDER / "a" / "test_b.py"), Item(TESTS / "test_env.py")
    pytest_collection_modifyitems(None, [inside, nested, outside])
    assert (inside.marks, nested.marks, outside.marks) == (["sb3"], ["sb3"], [])


def test_the_rllib_run_leaves_out_the_folder_and_the_mark():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    (rule,) = [line for line in makefile.splitlines() if line.startswith("\t$(RLLIB_BIN)/python $(PYTEST)")]
    assert '--ignore=tests/sb3 -m "not sb3"' in rule
    assert "--deselect" not in makefile and "::" not in rule  # nothing chosen by name
