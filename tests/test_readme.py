"""The README is a short product page whose links resolve, the words for users carry no working notes, and
the package version has one source.

The README's relative links and images must name files of the repository (and its ``#anchors`` headings
of the file they point into, as GitHub makes them); the detail lives in the documentation site (docs/).
"""

from __future__ import annotations

import importlib.metadata
import re
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_LINES = 250
# words of a working session, not of a product: none of them belongs in what users and maintainers read
PROCESS_WORDS = ("this stop", "issue #", "load average")

_FENCE = re.compile(r"^(```|~~~)")
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HTML_SRC = re.compile(r"""<(?:img|a|source)\b[^>]*?\b(?:src|href)=["']([^"']+)["']""", re.IGNORECASE)
_INLINE_CODE = re.compile(r"`[^`]*`")


def _prose_lines(text: str, inline_code: bool = False) -> list[str]:
    """The lines outside fenced code blocks, with inline code removed unless ``inline_code``."""
    lines, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line if inline_code else _INLINE_CODE.sub("", line))
    return lines


def links(text: str) -> list[str]:
    """Every link and image target of a Markdown text (Markdown and HTML syntax), outside code."""
    found = []
    for line in _prose_lines(text):
        found += _LINK.findall(line) + _HTML_SRC.findall(line)
    return found


def anchors(text: str) -> set[str]:
    """The anchors GitHub gives a Markdown file's headings: lower case, punctuation dropped, spaces to
    hyphens, a repeated slug numbered ``-1``, ``-2``, ..."""
    seen: dict[str, int] = {}
    result = set()
    for line in _prose_lines(text, inline_code=True):
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not match:
            continue
        title = re.sub(r"<[^>]+>", "", match.group(1))
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title)  # a link in a heading: its text
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        result.add(slug if count == 0 else f"{slug}-{count}")
    return result


def broken_links(markdown: Path) -> list[str]:
    """The relative links and images of a Markdown file whose file, or anchor in a Markdown file, is missing."""
    text = markdown.read_text(encoding="utf-8")
    broken = []
    for link in links(text):
        parts = urlsplit(link)
        if parts.scheme or parts.netloc or link.startswith("//"):
            continue  # an address on the web
        target = (markdown.parent / unquote(parts.path)).resolve() if parts.path else markdown
        if not target.exists():
            broken.append(f"{link} (no file)")
        elif ROOT not in target.parents and target != ROOT:
            broken.append(f"{link} (outside the repository)")
        elif parts.fragment and target.suffix == ".md" and unquote(parts.fragment) not in anchors(target.read_text(encoding="utf-8")):
            broken.append(f"{link} (no anchor)")
    return broken


def test_the_readme_is_short():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_LINES, f"README.md has {len(lines)} lines, at most {MAX_LINES}: move detail to docs/"


def test_every_link_and_image_of_the_readme_resolves():
    text = README.read_text(encoding="utf-8")
    assert links(text), "no link found: the link parser is broken"
    assert broken_links(README) == []


def test_the_readme_shows_the_commands_and_every_task():
    from leg_env.tasks import REGISTRY

    text = README.read_text(encoding="utf-8")
    assert "make train" in text and "make test" in text
    for env_id in REGISTRY:
        assert f"`{env_id}`" in text, f"{env_id} is not in the README's task table"
    assert (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1] == "make test"


def test_the_link_check_finds_broken_links(tmp_path, monkeypatch):
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    (tmp_path / "a.md").write_text("# A title, with `code`\n\n## Twice\n\n## Twice\n")
    page = tmp_path / "README.md"
    page.write_text(
        "# Page\n\n[ok](a.md) [ok](a.md#a-title-with-code) [ok](#page) [ok](a.md#twice-1) [web](https://example.org/x)\n"
        "![gone](missing.gif) [bad](a.md#nowhere) [bad](#nowhere) <img src=\"gone.png\">\n"
        "`[not a link](nowhere.md)`\n\n```\n[not a link](nowhere.md)\n```\n"
    )
    assert broken_links(page) == ["missing.gif (no file)", "a.md#nowhere (no anchor)", "#nowhere (no anchor)", "gone.png (no file)"]


def _user_facing_files() -> list[Path]:
    files = [README, *sorted((ROOT / "docs").glob("*.md"))]
    if (ROOT / "CHANGELOG.md").is_file():
        files.append(ROOT / "CHANGELOG.md")
    for folder in ("leg_env", "train", "policies", "benchmarks"):
        for suffix in ("*.py", "*.md"):
            files += sorted((ROOT / folder).rglob(suffix))
    return files


@pytest.mark.parametrize("phrase", PROCESS_WORDS)
def test_no_working_notes_in_what_users_read(phrase):
    found = []
    for path in _user_facing_files():
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if phrase in line.lower():
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:120]}")
    assert found == []


def test_the_changelog_names_every_id():
    from leg_env.tasks import REGISTRY

    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert text.startswith("# Changelog") and "Keep a Changelog" in text
    for env_id in REGISTRY:
        assert env_id in text, f"{env_id} has no entry in CHANGELOG.md"


def test_the_version_has_one_source():
    """``leg_env.__version__`` is the version: the installed metadata reads it (pyproject's dynamic version),
    and so does the documentation."""
    import leg_env

    assert importlib.metadata.version("leg-env") == leg_env.__version__
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert re.search(r'^dynamic\s*=\s*\[[^\]]*"version"', pyproject, re.MULTILINE), "pyproject.toml states a version of its own"
    assert not re.search(r"^version\s*=\s*\"", pyproject, re.MULTILINE), "pyproject.toml states a version of its own"
    assert re.search(r'^version\s*=\s*\{\s*attr\s*=\s*"leg_env\.__version__"\s*\}', pyproject, re.MULTILINE)
    conf = (ROOT / "docs" / "conf.py").read_text(encoding="utf-8")
    assert re.search(r"^release = version = leg_env.__version__$", conf, re.MULTILINE), "docs/conf.py must take its release from leg_env.__version__"
