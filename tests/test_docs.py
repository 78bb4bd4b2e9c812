"""The documentation site (docs/) builds with every warning an error, and its links resolve.

The build is ``python -m sphinx -W --keep-going -n -b html docs <tmp>/html``: MyST Markdown pages, the
API pages by autodoc, the lesson notebook executed by myst-nb, and one page per registered id generated
by ``docs/conf.py`` (into ``docs/_generated/``, git-ignored). ``-n`` makes every unresolved cross-reference
a warning; the built HTML is then scanned for relative links and images whose file (or anchor) is missing.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
TIME_LIMIT = 120.0  # [s] the whole build (about 6 s on 2 cores, the notebook's execution included)


def sphinx_build(src: Path, out: Path) -> tuple[subprocess.CompletedProcess, float]:
    env = dict(os.environ, MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-b", "html", "-d", str(out / "doctrees"), str(src), str(out / "html")]
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    return proc, time.perf_counter() - start


class _Links(HTMLParser):
    """The ``href`` and ``src`` of a page, and the ids it defines."""

    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if value is None:
                continue
            if name in ("href", "src") and tag in ("a", "img", "link", "script", "source", "video"):
                self.links.append(value)
            elif name == "id" or (name == "name" and tag == "a"):
                self.ids.add(value)


def broken_links(html_dir: Path) -> list[str]:
    """Every relative link or image of the built site whose file, or anchor in it, does not exist."""
    pages: dict[Path, _Links] = {}
    for page in html_dir.rglob("*.html"):
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        pages[page.resolve()] = parser
    broken = []
    for page, parser in sorted(pages.items()):
        for link in parser.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith("//"):
                continue  # an external address: not this site's
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            where = f"{page.relative_to(html_dir.resolve())}: {link}"
            if not target.is_file():
                broken.append(f"{where} (no file)")
            elif parts.fragment and target in pages and unquote(parts.fragment) not in pages[target].ids:
                broken.append(f"{where} (no anchor)")
    return broken


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs")
    proc, elapsed = sphinx_build(DOCS, out)
    return proc, elapsed, out / "html"


def test_the_site_builds_without_a_warning(site):
    proc, elapsed, html = site
    assert proc.returncode == 0, f"sphinx failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-8000:]}"
    assert "WARNING" not in proc.stderr.replace("[IPKernelApp] WARNING", ""), proc.stderr[-8000:]
    assert (html / "index.html").is_file()
    assert elapsed < TIME_LIMIT, f"the docs build took {elapsed:.1f} s"


def test_every_registered_id_has_its_task_page(site):
    from leg_env.tasks import REGISTRY

    proc, _, html = site
    assert proc.returncode == 0, proc.stderr[-8000:]
    index = (html / "_generated" / "tasks" / "index.html").read_text(encoding="utf-8")
    for env_id, (task, _) in REGISTRY.items():
        name = env_id.split("/", 1)[1]
        page = html / "_generated" / "tasks" / f"{name}.html"
        assert page.is_file(), f"no page for {env_id}"
        text = page.read_text(encoding="utf-8")
        assert env_id in text and f"leg_env.tasks.{task}" in text
        assert "reward_alive" in text  # the reward terms, read from the environment
        assert f"{name}.html" in index, f"{env_id} is not in the tasks' table of contents"


def test_the_lesson_is_executed_and_the_api_documented(site):
    proc, _, html = site
    assert proc.returncode == 0, proc.stderr[-8000:]
    lesson = (html / "_generated" / "lesson.html").read_text(encoding="utf-8")
    assert "cell_output" in lesson  # myst-nb ran the notebook (it is stored without outputs)
    api = (html / "api.html").read_text(encoding="utf-8")
    for module in ("leg_env.physics.dynamics", "leg_env.physics.contact", "leg_env.physics.hybrid", "leg_env.physics.integrate", "leg_env.physics.derivatives", "leg_env.physics.params", "leg_env.envs", "leg_env.identify", "leg_env.autograd"):
        assert f'id="module-{module}"' in api, f"{module} is not documented"
    benchmarks = (html / "benchmarks.html").read_text(encoding="utf-8")
    assert "Environment speed" in benchmarks and "Soak" in benchmarks


def test_internal_links_resolve(site):
    proc, _, html = site
    assert proc.returncode == 0, proc.stderr[-8000:]
    assert broken_links(html) == []


def test_the_link_check_finds_a_broken_link(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "index.html").write_text('<a href="sub/page.html#here">ok</a> <a href="https://example.org/x">ext</a>')
    (tmp_path / "sub" / "page.html").write_text('<h1 id="here">x</h1><a href="../index.html">up</a><img src="missing.png">'
                                                '<a href="../index.html#nowhere">bad anchor</a>')
    assert broken_links(tmp_path) == ["sub/page.html: missing.png (no file)", "sub/page.html: ../index.html#nowhere (no anchor)"]


def test_a_warning_fails_the_build(tmp_path):
    """The build command's ``-W -n``: a page with an unresolved reference does not build."""
    src = tmp_path / "src"
    src.mkdir()
    (src / "conf.py").write_text('extensions = ["myst_parser"]\n')
    (src / "index.md").write_text("# Title\n\nSee {doc}`a-page-that-does-not-exist`.\n")
    proc, _ = sphinx_build(src, tmp_path / "out")
    assert proc.returncode != 0
    assert "a-page-that-does-not-exist" in proc.stderr
