"""The run folder of ``train.ppo`` and ``train.rllib``: one training process at a time, and what a rerun does with it.

The steps of a run in its folder are ``train.run``'s; this module holds the two that guard the folder. What
differs between the trainers (the ``trainer`` entry of ``config.yaml``, the configuration entries a resume must
match, the files of a policy) is a ``RunKind``.

``RunLock`` makes a training process the folder's only writer. It holds an exclusive
``fcntl.flock`` on ``<run>/train.lock``, a file holding the process id, from before the folder
is inspected until the run ends. A second process refuses with ``RunLockedError``, naming the lock
file and that pid. The kernel drops the lock when its holder dies, so the lock file that a killed
process leaves behind is stale: the next run takes it over. This needs a POSIX system.

``prepare_run_folder`` decides, under the lock, whether a run starts afresh or resumes:

* ``--overwrite``: the run's files are deleted and training starts afresh;
* a folder with checkpoints resumes from the newest intact one, if its ``config.yaml`` matches (the
  same trainer and the same ``RunKind.resume_keys``; the trainer picks the checkpoint); with
  ``--no-resume`` it is refused;
* a started run that never reached a checkpoint (it failed, or was killed, before the first one)
  and has the same configuration is restarted: its partial files go, its ``command.txt`` stays;
* any other existing run is refused (a different configuration, or no record of one).

It also tidies what a killed process leaves: the temporary files of atomic writes, the temporary
folders of checkpoints being written, and a ``best/`` or ``last/`` directory caught in the middle of
being replaced.
"""

from __future__ import annotations

import os
import shlex
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import yaml

from train.checkpoints import checkpoint_dirs, file_mode, recover_snapshot

__all__ = ["RunFolderError", "RunLockedError", "RunLock", "RunKind", "prepare_run_folder", "run_locked", "LOCK_NAME",
           "runnable_command"]

LOCK_NAME = "train.lock"
RUN_FILES = (
    "config.yaml",
    "command.txt",
    "evaluations.json",
    "learning_curve.png",
    "checkpoints",
    "best",
    "last",
    "eval",  # train.evaluate's
    "model.zip",  # train.ppo's policy
    "vecnormalize.pkl",
    "tb",
    "module",  # train.rllib's policy
    "progress.json",
    "runners.json",
)
"""What a run of either trainer writes into its folder (the lock aside): what ``--overwrite`` deletes."""


@dataclass(frozen=True)
class RunKind:
    """What tells one trainer's run folders from the other's, and what a resume of them must match."""

    command: str
    """The trainer's command (``train.ppo``), for messages."""
    trainer: str | None
    """``config.yaml``'s ``trainer`` entry (None: a run without one, ``train.ppo``'s): a folder of another
    trainer is never resumed."""
    resume_keys: tuple[str, ...]
    """The configuration entries that define the training; a resume must match them."""
    policy_files: tuple[str, ...]
    """The files (or folders) of a policy: the selected one at the top of the run folder, and in ``best/``, ``last/``;
    a run that has them finished."""


class RunFolderError(Exception):
    """The run folder cannot be used as asked; the message says why and what to do."""


class RunLockedError(RunFolderError):
    """Another process is training into the run folder."""


class ConfigMismatchError(RunFolderError, ValueError):
    """The folder holds a run with a different configuration."""


class ExistingRunError(RunFolderError, FileExistsError):
    """The folder holds a run that this invocation may not continue or replace."""


class RunLock:
    """Exclusive lock on a run folder, as a context manager (see the module docstring)."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / LOCK_NAME
        self.stale_pid: str | None = None
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        import fcntl

        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, file_mode())
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_all(fd) or "unknown (it is starting)"
                os.close(fd)
                raise RunLockedError(
                    f"{self.path.parent} is in use: process {holder} is training into it and holds its lock "
                    f"{self.path}; wait for it to finish or stop it (a lock left by a process that no longer "
                    "runs is taken over automatically)"
                ) from None
            try:
                current = os.stat(self.path)
            except FileNotFoundError:
                current = None
            opened = os.fstat(fd)
            if current is not None and (current.st_dev, current.st_ino) == (opened.st_dev, opened.st_ino):
                break
            os.close(fd)  # the holder released and removed the file between our open and flock: retry
        self.stale_pid = _read_all(fd) or None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            os.unlink(self.path)  # removed while still held, so no other process can lock a file about to vanish
        except FileNotFoundError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


T = TypeVar("T")


def run_locked(out: Path, run: Callable[[], T]) -> T:
    """Make the folder ``out`` and return ``run()``, called while holding the folder's lock (``RunLock``); taking
    over a lock left by a process that no longer runs is said on stderr."""
    out.mkdir(parents=True, exist_ok=True)
    with RunLock(out) as lock:
        if lock.stale_pid is not None:
            print(f"took over the lock {lock.path} left by process {lock.stale_pid}, which no longer runs", file=sys.stderr, flush=True)
        return run()


def _read_all(fd: int) -> str:
    os.lseek(fd, 0, os.SEEK_SET)
    return os.read(fd, 64).decode(errors="replace").strip()


def _saved_config(out: Path) -> dict | None:
    path = out / "config.yaml"
    if not path.is_file():
        return None
    try:
        saved = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise RunFolderError(f"cannot read {path}: {e}; use another --out, or --overwrite to replace the run") from e
    return saved if isinstance(saved, dict) else {}


def _remove(paths) -> None:
    for path in paths:
        shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()


def _tidy(out: Path, kind: RunKind) -> None:
    """Remove what an interrupted atomic write left in ``out`` and finish an interrupted snapshot swap."""
    for name in ("best", "last", *kind.policy_files):
        recover_snapshot(out / name)
    prefixes = tuple(f".{name}." for name in RUN_FILES)
    _remove(p for p in out.iterdir() if p.name.startswith(prefixes))
    checkpoints = out / "checkpoints"
    if checkpoints.is_dir():  # a checkpoint being written when its process was killed
        _remove(p for p in checkpoints.iterdir() if p.name.startswith(".") and p.is_dir())


def _differences(saved: dict | None, config: dict, kind: RunKind) -> list[str]:
    """The entries in which the saved configuration differs from ``config``, ``trainer`` first."""
    saved = saved or {}
    if saved.get("trainer") != kind.trainer:
        return ["trainer"]
    return [key for key in kind.resume_keys if saved.get(key) != config.get(key)]


def prepare_run_folder(out: Path, config: dict, kind: RunKind, resume: bool = True, overwrite: bool = False, log=None) -> bool:
    """Make ``out`` ready for the run ``config`` of a ``kind`` of trainer (see the module docstring); True to resume
    from its checkpoints.

    The caller holds the folder's ``RunLock``. ``log`` receives a line when a failed start is restarted.

    Raises:
        ConfigMismatchError: the folder holds a run with a different configuration (a ``ValueError``).
        ExistingRunError: a run that may not be resumed or restarted (a ``FileExistsError``).
        RunFolderError: its ``config.yaml`` cannot be read.
    """
    out = Path(out)
    _tidy(out, kind)
    existing = [out / name for name in RUN_FILES if (out / name).exists()]
    if overwrite:
        _remove(existing)
        return False
    if not existing:
        return False
    has_checkpoint = bool(checkpoint_dirs(out / "checkpoints"))
    saved = _saved_config(out)
    finished = any((out / name).exists() for name in kind.policy_files)
    restartable = not has_checkpoint and saved is not None and not finished
    if (has_checkpoint and resume) or restartable:
        different = _differences(saved, config, kind)
        if different:
            raise ConfigMismatchError(
                f"{out} holds a run with a different configuration ({', '.join(different)} differ); "
                "use another --out, or --overwrite to replace it"
            )
        if has_checkpoint:
            return True
        if log is not None:
            log(f"{out}: the previous start ended before its first checkpoint; starting it again")
        _remove(p for p in existing if p.name != "command.txt")
        return False
    why = "has a checkpoint but --no-resume was given" if has_checkpoint else "already holds a run"
    raise ExistingRunError(f"{out} {why}; use another --out, or --overwrite to replace it")


def runnable_command() -> str:
    """This process's command line as anyone can run it (``command.txt`` of a run folder): ``python -m
    train.ppo ...``, the interpreter's path, a machine's own, written as ``python``."""
    argv = list(getattr(sys, "orig_argv", None) or [sys.executable, *sys.argv])
    return shlex.join(["python", *argv[1:]])
