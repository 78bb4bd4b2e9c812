"""leg-env as a user gets it: the built wheel in a fresh venv whose files and HOME cannot be written.

Shared by ``tests/test_wheel.py`` and ``benchmarks/cold_start.py``::

    work = Path(tempfile.mkdtemp())
    built = build(work)                      # an sdist from a copy of the sources, then the wheel from the sdist
    venv = make_venv(work, built.wheel)      # a fresh venv: the wheel and its runtime dependencies, no bytecode
    with read_only(venv) as locked:          # the venv, HOME and the working directory cannot be written
        done = locked.run(code)              # a fresh process of that venv, outside the repository
    cleanup(work)

The build runs without build isolation and without the network: ``python -m build --no-isolation`` when
the ``build`` package is installed, else the setuptools backend's ``build_sdist`` hook directly (the same
PEP 517 call), then ``pip wheel --no-build-isolation --no-index`` on the sdist, so the sdist must carry
every file the build needs. The runtime dependencies are installed at the versions of the running
interpreter's environment, from wheels in a local directory (``pip install --no-index --find-links``):
downloaded from the package index (``pip download``, usually served from pip's cache), or, when that
fails (no network), packed from the distributions installed here. Nothing is byte-compiled at install
(``--no-compile``), so the venv holds no ``__pycache__`` and no other cache to start from.

Read-only: every file and directory of the venv, of HOME and of the working directory loses its write
bits. Root ignores those, so as root the immutable attribute is set too (``chattr +i``); where that is not
supported, the processes run as the unprivileged user ``nobody`` instead (``setpriv`` or ``runuser``).
Either way a probe process checks that it can write nowhere before anything is run, and
:func:`read_only` undoes the locks on leaving, whatever happened.
"""

from __future__ import annotations

import base64
import contextlib
import csv
import hashlib
import importlib.metadata
import importlib.util
import io
import json
import os
import pwd
import re
import shutil
import stat
import subprocess
import sys
import tarfile
import textwrap
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE_FILES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE")
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", "*.so", "*.pyd", "*.nbi", "*.nbc", "*.egg-info")
# variables that would let a child process find the repository, a cache or a bytecode location
UNSAFE_ENV = re.compile(r"^(PYTHON\w*|VIRTUAL_ENV|CONDA_\w+|XDG_\w+|NUMBA_\w+|PIP_\w+|__PYVENV_LAUNCHER__)$")


def _run(cmd: list[str], timeout: float = 600, **kwargs) -> subprocess.CompletedProcess:
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kwargs)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} exited with {done.returncode}:\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}")
    return done


# ---------------------------------------------------------------- build


@dataclass
class Build:
    """The sdist, the wheel built from it, and the sources they were built from."""

    source: Path
    sdist: Path
    wheel: Path
    log: str


def copy_sources(dest: Path) -> Path:
    """Copy what the sdist is made from (the package and the top-level build files) to ``dest``."""
    dest.mkdir(parents=True)
    for name in SOURCE_FILES:
        shutil.copy(ROOT / name, dest / name)
    shutil.copytree(ROOT / "leg_env", dest / "leg_env", ignore=IGNORED)
    return dest


def build_sdist(source: Path, out: Path) -> Path:
    """The sdist of ``source`` in ``out``, built without isolation (no download of the build backend)."""
    out.mkdir(parents=True, exist_ok=True)
    spec = importlib.util.find_spec("build")
    if spec is not None and spec.origin is not None:  # the `build` package, not a checkout's build/ directory
        _run([sys.executable, "-m", "build", "--sdist", "--no-isolation", "--outdir", str(out), str(source)], cwd=out)
    else:  # what `build --no-isolation` calls: the backend's PEP 517 hook
        hook = f"import setuptools.build_meta as backend; print(backend.build_sdist({str(out)!r}))"
        _run([sys.executable, "-c", hook], cwd=source)
    (sdist,) = out.glob("leg_env-*.tar.gz")
    return sdist


def build_wheel_from_sdist(sdist: Path, out: Path) -> tuple[Path, str]:
    """The wheel built from the sdist alone (nothing else of the sources), and pip's output."""
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "--disable-pip-version-check", "-w", str(out), str(sdist)]
    done = _run(cmd)
    (wheel,) = out.glob("leg_env-*.whl")
    return wheel, done.stdout + done.stderr


def build(work: Path) -> Build:
    """An sdist from a copy of the sources, then the wheel from that sdist, all under ``work``."""
    source = copy_sources(work / "src")
    sdist = build_sdist(source, work / "sdist")
    wheel, log = build_wheel_from_sdist(sdist, work / "dist")
    return Build(source, sdist, wheel, log)


def sdist_names(sdist: Path) -> list[str]:
    """The paths in the sdist, relative to its top directory."""
    with tarfile.open(sdist) as tar:
        return [name.split("/", 1)[1] for name in tar.getnames() if "/" in name]


# ---------------------------------------------------------------- runtime dependencies


def _requirement(text: str):
    try:
        from packaging.requirements import Requirement
    except ImportError:  # pip vendors it
        from pip._vendor.packaging.requirements import Requirement
    return Requirement(text)


def runtime_distributions(wheel: Path) -> dict[str, str]:
    """The wheel's runtime dependencies and theirs, at the versions installed here: {name: version}.

    Extras are left out; markers are evaluated for the running interpreter (the fresh venv's base).
    """
    with zipfile.ZipFile(wheel) as z:
        metadata = z.read(next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))).decode()
    todo = [line.split(":", 1)[1].strip() for line in metadata.splitlines() if line.startswith("Requires-Dist:")]
    found: dict[str, str] = {}
    while todo:
        req = _requirement(todo.pop())
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        if name in found:
            continue
        dist = importlib.metadata.distribution(name)  # a dependency not installed here: PackageNotFoundError
        found[name] = dist.version
        todo += dist.requires or []
    return found


def download_wheels(pins: dict[str, str], dest: Path) -> None:
    """``pip download`` the pinned wheels (binary only, no resolution) into ``dest``."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--disable-pip-version-check", "--retries", "1", "--timeout", "20", "-d", str(dest)]
    _run(cmd + [f"{name}=={version}" for name, version in sorted(pins.items())], timeout=900)


def _record_hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def pack_installed(name: str, dest: Path) -> Path:
    """A wheel of the installed distribution ``name``: its files in site-packages as installed.

    Byte-code, the installer's records and files outside site-packages (console scripts) are left out;
    the tag is the first of its ``WHEEL`` file, the one pip installed it under.
    """
    dist = importlib.metadata.distribution(name)
    tags = [line.split(":", 1)[1].strip() for line in (dist.read_text("WHEEL") or "").splitlines() if line.startswith("Tag:")]
    if not tags:
        raise RuntimeError(f"{name} was not installed from a wheel (no tag in its WHEEL file)")
    files = [f for f in dist.files or [] if not f.as_posix().startswith("..")]
    info = next(f.parts[0] for f in files if f.parts[0].endswith(".dist-info"))
    skip = {f"{info}/{n}" for n in ("RECORD", "INSTALLER", "REQUESTED", "direct_url.json")}
    stem = re.sub(r"[-_.]+", "_", dist.metadata["Name"]).lower()
    path = dest / f"{stem}-{dist.version}-{tags[0]}.whl"
    record = io.StringIO()
    writer = csv.writer(record, lineterminator="\n")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(files, key=lambda f: (f.parts[0] == info, f.as_posix())):  # .dist-info last
            rel = f.as_posix()
            if rel in skip or "__pycache__" in f.parts or rel.endswith(".pyc"):
                continue
            source = Path(dist.locate_file(f))
            if not source.is_file():
                continue
            data = source.read_bytes()
            entry = zipfile.ZipInfo(rel, date_time=(1980, 1, 1, 0, 0, 0))
            entry.external_attr = (stat.S_IMODE(source.stat().st_mode) | stat.S_IFREG) << 16
            entry.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(entry, data)
            writer.writerow([rel, _record_hash(data), len(data)])
        writer.writerow([f"{info}/RECORD", "", ""])
        z.writestr(f"{info}/RECORD", record.getvalue())
    return path


def runtime_wheels(wheel: Path, dest: Path) -> str:
    """Fill ``dest`` with wheels of the runtime dependencies; say where they came from."""
    dest.mkdir(parents=True, exist_ok=True)
    pins = runtime_distributions(wheel)
    try:
        download_wheels(pins, dest)
        return "downloaded: " + ", ".join(f"{n}=={v}" for n, v in sorted(pins.items()))
    except (RuntimeError, subprocess.TimeoutExpired):
        for old in dest.glob("*.whl"):
            old.unlink()
        for name in pins:
            pack_installed(name, dest)
        return "packed from the installed distributions: " + ", ".join(f"{n}=={v}" for n, v in sorted(pins.items()))


# ---------------------------------------------------------------- the venv


@dataclass
class Venv:
    """A fresh venv with the wheel installed, an empty HOME and an empty working directory."""

    root: Path
    python: Path
    site_packages: Path
    home: Path
    cwd: Path
    wheels: str  # where the runtime dependencies' wheels came from

    def environ(self) -> dict[str, str]:
        """The child's environment: nothing that points at the repository, a cache or another venv."""
        env = {k: v for k, v in os.environ.items() if not UNSAFE_ENV.match(k)}
        env.update(HOME=str(self.home), PATH=f"{self.root / 'bin'}{os.pathsep}{env.get('PATH', '')}")
        return env


def make_venv(work: Path, wheel: Path) -> Venv:
    """A fresh venv under ``work`` (no system site-packages, no pip) with the wheel and its dependencies.

    The main environment's pip installs into it (``pip --python``), from local wheels only and without
    byte-compiling. ``work`` is opened to every user (so that ``nobody`` can run it if needed).
    """
    work.chmod(0o755)
    root = work / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(root)])
    python = root / "bin" / "python"
    wheelhouse = work / "wheelhouse"
    source = runtime_wheels(wheel, wheelhouse)
    cmd = [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-index", "--find-links", str(wheelhouse), "--no-compile", "--disable-pip-version-check", "--no-cache-dir", str(wheel)]
    _run(cmd)
    site = Path(_run([str(python), "-I", "-B", "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"]).stdout.strip())
    for name in ("home", "cwd"):
        (work / name).mkdir()
    return Venv(root, python, site, work / "home", work / "cwd", source)


# ---------------------------------------------------------------- read-only


PROBE = textwrap.dedent(
    """
    import json, os, sys
    wrote = []
    for where in sys.argv[1:]:
        for attempt in ("create", "mkdir", "append"):
            try:
                if attempt == "create":
                    open(os.path.join(where, "probe.txt"), "x").close()
                elif attempt == "mkdir":
                    os.mkdir(os.path.join(where, "__pycache__"))
                else:
                    existing = next((os.path.join(where, n) for n in sorted(os.listdir(where)) if os.path.isfile(os.path.join(where, n))), None)
                    if existing is None:
                        continue
                    open(existing, "a").close()
                wrote.append(f"{attempt} in {where}")
            except OSError:
                pass
    print(json.dumps(wrote))
    """
)


def walk(top: Path) -> list[Path]:
    """``top`` and everything under it, symlinks listed but not followed (a venv's ``lib64``)."""
    out = [top]
    for here, dirs, files in os.walk(top):
        out += [Path(here, name) for name in dirs + files]
    return out


def snapshot(*tops: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``tops`` with its size and modification time."""
    return {str(p): (p.lstat().st_size, p.lstat().st_mtime_ns) for top in tops for p in walk(top)}


@dataclass
class Locked:
    """A venv locked read-only: run fresh processes in it."""

    venv: Venv
    how: str  # "immutable (chattr +i)", "write bits off" or "as nobody, write bits off"
    prefix: list[str] = field(default_factory=list)  # the command that drops to an unprivileged user

    def run(self, code: str, timeout: float = 600) -> subprocess.CompletedProcess:
        """``python -c code`` in the venv, as the locked user, cwd the empty working directory."""
        cmd = [*self.prefix, str(self.venv.python), "-c", code]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=self.venv.environ(), cwd=self.venv.cwd)

    def writable(self) -> list[str]:
        """What a process could write in the venv, HOME or the working directory (empty when locked)."""
        places = [self.venv.site_packages, self.venv.site_packages / "leg_env", self.venv.root, self.venv.home, self.venv.cwd]
        done = self.run(PROBE.replace("sys.argv[1:]", repr([str(p) for p in places])), timeout=120)
        if done.returncode != 0:
            raise RuntimeError(done.stderr)
        return json.loads(done.stdout)


def _unprivileged() -> list[str] | None:
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        return None
    if shutil.which("setpriv"):
        return ["setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups", "--"]
    if shutil.which("runuser"):
        return ["runuser", "-u", "nobody", "--"]
    return None


def _chattr(flag: str, paths: list[Path]) -> bool:
    ok = True
    for i in range(0, len(paths), 500):
        done = subprocess.run(["chattr", flag, *map(str, paths[i : i + 500])], capture_output=True, text=True)
        ok = ok and done.returncode == 0
    return ok


@contextlib.contextmanager
def read_only(venv: Venv):
    """Lock the venv, HOME and the working directory against writes; yield a :class:`Locked`.

    The locks are undone on leaving. Raises ``RuntimeError`` if no way of locking holds (a probe process
    could still write).
    """
    tops = [venv.root, venv.home, venv.cwd]
    paths = [p for top in tops for p in walk(top) if not p.is_symlink()]
    modes = {p: stat.S_IMODE(p.stat().st_mode) for p in paths}
    immutable: list[Path] = []
    try:
        for p in paths:
            p.chmod(modes[p] & ~0o222)
        locked = Locked(venv, "write bits off")
        if os.geteuid() == 0:
            if shutil.which("chattr") and _chattr("+i", paths):
                immutable = paths
                locked = Locked(venv, "immutable (chattr +i)")
            else:  # chattr is missing or the file system does not support it
                _chattr("-i", paths)
                prefix = _unprivileged()
                if prefix is None:
                    raise RuntimeError("running as root without chattr +i and without an unprivileged user: cannot make the venv read-only")
                locked = Locked(venv, "as nobody, write bits off", prefix)
        wrote = locked.writable()
        if wrote:
            raise RuntimeError(f"the venv is not read-only ({locked.how}): a process could {wrote}")
        yield locked
    finally:
        if immutable:
            _chattr("-i", immutable)
        for p in paths:
            if p.exists() and not p.is_symlink():
                p.chmod(modes[p])


def cleanup(work: Path) -> None:
    """Remove ``work`` (after :func:`read_only` has undone its locks)."""
    shutil.rmtree(work, ignore_errors=True)


def machine() -> dict[str, str]:
    """The machine and the versions a result was measured with."""
    import platform

    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "platform": platform.platform(),
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "python": platform.python_version(),
        "numpy": importlib.metadata.version("numpy"),
        "gymnasium": importlib.metadata.version("gymnasium"),
    }
