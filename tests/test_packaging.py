"""Packaging: the wheel carries the SPDX licence, LICENSE, py.typed and the Gymnasium floor, and builds without warnings."""

import re
import shutil
import subprocess
import sys
import tarfile
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GYMNASIUM_FLOOR = "1.1"  # gymnasium.vector.AutoresetMode, imported by the vector env, arrived in 1.1.0


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> tuple[Path, str]:
    """The wheel built from a copy of the sources (the tree stays clean), and the build's output."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "leg_env", src / "leg_env", ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc", "*.so"))
    cmd = [sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(tmp / "dist"), str(src)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    (wheel,) = (tmp / "dist").glob("leg_env-*.whl")
    return wheel, result.stdout + result.stderr


def test_the_build_prints_no_deprecation_warning(build):
    _, output = build
    assert not re.search(r"deprecat", output, re.IGNORECASE), [line for line in output.splitlines() if "eprecat" in line.lower()]


def test_wheel_has_the_licence_and_py_typed(build):
    wheel, _ = build
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        assert "leg_env/py.typed" in names
        (licence,) = [n for n in names if n.endswith(".dist-info/licenses/LICENSE")]
        text = z.read(licence).decode()
        assert text.startswith("MIT License") and "Copyright (c) 2026 leg-env developers" in text
        metadata = z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "License-Expression: MIT" in metadata.splitlines()
    assert f"Requires-Dist: gymnasium>={GYMNASIUM_FLOOR}" in metadata.splitlines()


def test_wheel_carries_the_compiled_core_built_from_source(build):
    wheel, output = build
    assert re.search(r"\S+\.whl$", wheel.name) and "-py3-none-any" not in wheel.name  # a platform wheel
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    assert any(re.fullmatch(r"leg_env/_core/kernels\..*(so|pyd)", n) for n in names), names
    assert "-ffp-contract=off" in output  # the core's flags reached the compiler


def test_pyproject_declares_an_spdx_licence():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    assert not any("License ::" in c for c in project.get("classifiers", []))  # PEP 639: the expression replaces them


def test_the_sdist_leaves_out_the_research_records(tmp_path):
    """``research/`` (the probe configurations, their learning pages and what they taught) sits beside the package in a
    checkout; the sdist built with it there carries none of it (MANIFEST.in prunes it), only the package's files."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc", "*.so", "*.egg-info")
    for folder in ("leg_env", "research"):
        shutil.copytree(ROOT / folder, src / folder, ignore=ignore)
    assert (src / "research" / "README.md").is_file()
    hook = f"import setuptools.build_meta as backend; print(backend.build_sdist({str(tmp_path / 'dist')!r}))"
    result = subprocess.run([sys.executable, "-c", hook], cwd=src, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    (sdist,) = (tmp_path / "dist").glob("leg_env-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = [name.split("/", 1)[1] for name in tar.getnames() if "/" in name]
    assert "leg_env/__init__.py" in names and "leg_env/_core/module.c" in names
    assert [n for n in names if n.startswith("research")] == []
