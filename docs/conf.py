"""Sphinx configuration of the leg-env documentation (MyST Markdown, myst-nb for the lesson notebook).

Build: ``python -m sphinx -W --keep-going -n -b html docs <out>/html``. At start-up (``builder-inited``)
this file writes the generated pages into ``docs/_generated/`` (git-ignored): one page per registered
environment id, made from its task module's docstring and from the environment itself (its spaces and
reward terms), and a copy of the lesson notebook, which myst-nb executes during the build.
"""

from __future__ import annotations

import inspect
import os
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
GENERATED = DOCS / "_generated"
sys.path.insert(0, str(ROOT))
# the lesson's kernel inherits this environment: its figures become the page's images (inline), whatever
# backend the build was started with (a headless one, say)
os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"

project = "leg-env"
author = "leg-env authors"
copyright = "leg-env authors"
import leg_env  # noqa: E402  (after the path is set: the checkout's package)

release = version = leg_env.__version__

extensions = [
    "myst_nb",  # MyST Markdown (it loads myst_parser) and executable notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints"]
html_theme = "alabaster"
html_static_path: list[str] = []

myst_enable_extensions = ["colon_fence", "dollarmath", "amsmath"]
myst_heading_anchors = 0
suppress_warnings = ["myst.header"]  # the docstrings' sections start at "##" under the page's title

# the lesson notebook is stored without outputs: execute it at every build, a failing cell fails the build
nb_execution_mode = "force"
nb_execution_timeout = 120
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_inherit_docstrings = False  # Gymnasium's own docstrings of reset, step and render are its to document
napoleon_google_docstring = True
napoleon_numpy_docstring = True

# types from libraries with no inventory here (the build needs no network): named, not linked
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|gymnasium|gym|torch|collections|typing|enum|dataclasses|argparse)(\..*)?"),
    (r"py:class", r"(optional )?(NDArray|ArrayLike|ndarray|callable|array_like|float|int|bool|str|dict|tuple|list)"),
    # the generic names of Gymnasium's signatures, and classes documented with their tasks, not here
    (r"py:class", r"(ObsType|ActType|AutoresetMode|StanceConfig|PushConfig|HopConfig|observation)"),
    (r"py:exc", r"(leg_env\.checks\.)?ArgumentTypeError"),
]


# ---------------------------------------------------------------------------------------------------------
# the generated pages

def _gifs() -> dict[str, Path]:
    """The shipped evaluation GIF of each id (``policies/<run>/eval/*.gif``, the id from its config.yaml)."""
    found: dict[str, Path] = {}
    for gif in sorted(ROOT.glob("policies/*/eval/*.gif")):
        config = gif.parent.parent / "config.yaml"
        if not config.is_file():
            continue
        for line in config.read_text().splitlines():
            if line.startswith("env_id:"):
                found.setdefault(line.split(":", 1)[1].strip().strip("'\""), gif)
    return found


def _is_markdown(doc: str) -> bool:
    """Gymnasium-style docstrings have Markdown sections (``## Description``)."""
    return any(line.startswith("## ") for line in inspect.cleandoc(doc).splitlines())


def _rst_is_clean(text: str) -> bool:
    """Whether docutils parses ``text`` as reStructuredText without a warning."""
    import docutils.core
    import docutils.utils

    settings = {"report_level": 5, "halt_level": 5, "warning_stream": False}
    doctree = docutils.core.publish_doctree(text, settings_overrides=settings)
    messages = doctree.findall(lambda node: node.tagname == "system_message")
    return all(message["level"] < docutils.utils.Reporter.WARNING_LEVEL for message in messages)


def _docstring_block(doc: str) -> str:
    """A docstring as page source: Markdown if it has Markdown sections, reStructuredText if it parses as
    such without a warning, else the text as it is (a literal block)."""
    doc = inspect.cleandoc(doc)
    if _is_markdown(doc):
        # one level down: the sections sit under the page's own sections
        return "\n".join("#" + line if line.startswith("## ") else line for line in doc.splitlines())
    if _rst_is_clean(doc):
        return "```{eval-rst}\n" + doc + "\n```"
    return "```text\n" + doc + "\n```"


STABILITY = {"leg_env/PlanarLegHop-v4": ROOT / "benchmarks" / "results" / "stability"}
"""The gait stability results (``python -m train.stability``) shown on a task's page: the path without suffix."""


def _task_page(env_id: str, task: str, kwargs: dict, gif: Path | None) -> str:
    """The page of one id: its spaces and reward terms read from the environment, its task's docstring."""
    import importlib

    import gymnasium as gym

    module = importlib.import_module(f"leg_env.tasks.{task}")
    steps = gym.spec(env_id).max_episode_steps
    env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point")
    try:
        obs_shape = env.single_observation_space.shape
        act = env.single_action_space
        reward_keys = tuple(env.unwrapped.reward_keys)
    finally:
        env.close()
    name = env_id.split("/", 1)[1]
    lines = [
        f"# {name}",
        "",
        "| | |",
        "|---|---|",
        f"| id | `{env_id}` |",
        f"| task module | `leg_env.tasks.{task}` |",
        f"| keyword arguments of the id | `{kwargs!r}` |" if kwargs else "| keyword arguments of the id | none |",
        f"| observation space | `Box` of shape `{obs_shape}`, float32 |",
        f"| action space | `Box({act.low.min():g}, {act.high.max():g}, {act.shape})`, float32 |",
        f"| episode length | {steps} steps (truncated after them) |",
        "",
        "```python",
        "import gymnasium as gym",
        "import leg_env  # registers the ids",
        "",
        f'env = gym.make("{env_id}")',
        f'envs = gym.make_vec("{env_id}", num_envs=64, vectorization_mode="vector_entry_point")',
        "```",
        "",
        "## Reward terms",
        "",
        "The reward is the sum of these terms; each is also in the step's `info` under its name:",
        "",
        *[f"- `{key}`" for key in reward_keys],
        "",
    ]
    if gif is not None:
        target = GENERATED / "tasks" / f"{name}.gif"
        shutil.copyfile(gif, target)
        run = gif.parent.parent.name
        lines += ["## A trained policy", "", f"An episode of the shipped policy `policies/{run}` (its card says what it is):", "",
                  f"![An episode of {name}]({target.name})", ""]
        plots = {"hops.png": "a few hops, next to the baseline: COM height, contact mode, contact force, impulses",
                 "push_curve.png": "survival against the push impulse, next to the baselines",
                 "timeseries.png": "the first evaluation episode: base drift, torques and contact force, next to the baseline"}
        for plot, caption in plots.items():
            if (gif.parent / plot).is_file():
                copy = GENERATED / "tasks" / f"{name}-{plot}"
                shutil.copyfile(gif.parent / plot, copy)
                lines += [f"![{caption}]({copy.name})", "", f"*{caption[0].upper() + caption[1:]}.*", ""]
    analysis = STABILITY.get(env_id)
    if analysis is not None and analysis.with_suffix(".md").is_file():
        copy = GENERATED / "tasks" / f"{name}-stability.png"
        shutil.copyfile(analysis.with_suffix(".png"), copy)
        table = analysis.with_suffix(".md").read_text().split("\n", 1)[1]  # without its title
        lines += ["## Gait stability", "", "The return map of the hop cycle, composed from the step's exact Jacobians "
                  "([gait stability](../../stability.md)):", table,
                  f"![growth per hop and Floquet multipliers]({copy.name})", ""]
    lines += ["## The task", "", f"From the docstring of `leg_env.tasks.{task}`:", "", _docstring_block(module.__doc__), ""]
    return "\n".join(lines)


def _write(path: Path, text: str) -> None:
    """Write only a changed file (Sphinx rebuilds what changed)."""
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def generate(app=None) -> None:
    """Write the pages of ``docs/_generated/``: the tasks' pages and their index, and the lesson notebook."""
    import leg_env  # noqa: F401  (registers the ids)
    from leg_env.tasks import REGISTRY

    (GENERATED / "tasks").mkdir(parents=True, exist_ok=True)
    gifs = _gifs()
    names = []
    for env_id, (task, kwargs) in REGISTRY.items():
        name = env_id.split("/", 1)[1]
        names.append(name)
        _write(GENERATED / "tasks" / f"{name}.md", _task_page(env_id, task, kwargs, gifs.get(env_id)))
    for stale in (GENERATED / "tasks").glob("*.md"):
        if stale.stem not in names:
            stale.unlink()
    _write(GENERATED / "tasks" / "index.md", "\n".join([
        "# Tasks",
        "",
        f"Every id registered by `import leg_env` ({len(names)} of them). Each page is made from the task"
        " module's docstring and from the environment itself.",
        "",
        "```{toctree}",
        ":maxdepth: 1",
        "",
        *names,
        "```",
        "",
    ]))
    shutil.copyfile(ROOT / "examples" / "lesson.ipynb", GENERATED / "lesson.ipynb")
    _write(GENERATED / "core.md", _core_page())


def _core_page() -> str:
    """The compiled core's structs, field by field, and its entry points, argument by argument: from the module's own
    report of its one table of fields (``leg_env.physics.layout.FIELD_DOCS``) and of entry points
    (``leg_env._core.signatures()``)."""
    from leg_env._core import kernels, signatures

    lines = ["# The compiled core", "",
             "Read from the compiled module itself: every struct it shares with Python, written once as a list of fields in "
             "`leg_env/_core/structs.def`, and every entry point, a row of the table `ENTRIES` in `module.c` that one binder "
             "reads to fetch and check its arguments. A batch of robots is one numpy structured array per struct "
             "(`leg_env.physics.layout`).", "", "## Structs", ""]
    for struct, (itemsize, fields) in kernels.layouts().items():
        lines += [f"### `{struct}`", "", f"{itemsize} bytes" + (" (a task's fields, in the struct's union)" if "." in struct else "") + ".", "",
                  "| field | type | count | offset | what it holds |", "|---|---|---:|---:|---|"]
        lines += [f"| `{name}` | {kind} | {count} | {offset} | {doc} |" for name, offset, kind, count, doc in fields]
        lines.append("")
    lines += ["## Entry points", "", "Shape rules: N one row per robot (the first such argument sets N), M one row shared by every "
              "robot or one per robot, 1 one row, * any number of rows, T blocks of N rows.", ""]
    for name, sig in signatures().items():
        lines += [f"### `kernels.{name}`", "", sig["doc"] + (" Releases the GIL." if sig["releases_gil"] else ""), "",
                  "| argument | dtype | rows | values per row | role | accepted |", "|---|---|---|---:|---|---|"]
        for a in sig["args"]:
            ends = ["finite" if abs(x) == 1.7976931348623157e308 else ("+inf" if x == float("inf") else f"{x:g}") for x in a["range"] or ()]
            accepted = "" if a["range"] is None else f"{'(' if a['open'] else '['}{ends[0]}, {ends[1]}]"
            accepted += " whole" if a["whole"] else ""
            accepted += " or None" if a["optional"] else ""
            lines.append(f"| `{a['name']}` | {a['dtype']} | {a['rows'] or '-'} | {a['width'] or ('-' if not a['rows'] else 'its own')} | "
                         f"{a['role']} | {accepted} |")
        lines.append("")
    return "\n".join(lines)


_PROPERTY_DOCSTRINGS: dict[str, list[str]] = {}


def _docstring_for_autodoc(app, what, name, obj, options, lines) -> None:
    """Before napoleon: a Gymnasium-style (Markdown) docstring is summarised, with a link to its task pages;
    a property's docstring is kept for ``_property_as_written``."""
    if what in ("class", "module") and any(line.startswith("## ") for line in lines):
        summary = []
        for line in lines:
            if not line.strip() or line.startswith("## "):
                break
            summary.append(line)
        lines[:] = summary + ["", "Its full description, in Markdown, is on the pages of :doc:`the tasks </_generated/tasks/index>`.", ""]
    elif what == "property":
        _PROPERTY_DOCSTRINGS[name] = list(lines)


def _property_as_written(app, what, name, obj, options, lines) -> None:
    """After napoleon: a property's docstring as written (its type is the signature's), not ``type: description``."""
    if what == "property" and name in _PROPERTY_DOCSTRINGS:
        lines[:] = _PROPERTY_DOCSTRINGS.pop(name)


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", _docstring_for_autodoc, priority=400)
    app.connect("autodoc-process-docstring", _property_as_written, priority=600)
    return {"parallel_read_safe": True}
