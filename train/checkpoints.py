"""Training checkpoints, written atomically and read back with a fall-back to the previous intact one.

Layout under ``<run>/checkpoints/``::

    <num_timesteps>/model.zip          the PPO model (policy, optimiser, step counter)
    <num_timesteps>/vecnormalize.pkl   observation/return statistics (only when the run normalises)
    <num_timesteps>/progress.json      steps, wall time, evaluation history, resume count
    <num_timesteps>/rng.pkl            Python, NumPy and torch generator states
    <num_timesteps>.corrupt/           a checkpoint found unusable on resume, kept for inspection

``save_checkpoint`` writes a checkpoint into a hidden temporary folder and renames it into place,
so a process killed at any moment leaves only complete checkpoint folders (and hidden leftovers,
which the next save removes). It keeps the ``keep`` newest ones.

``load_checkpoint`` reads the newest one and checks every file: a missing, truncated or garbage
file, statistics missing although the run normalises (or present although it does not), or a
model whose step counter disagrees with its ``progress.json`` make the checkpoint unusable. It is
then moved aside to ``<name>.corrupt`` with a ``CheckpointWarning`` naming the file, and the
previous checkpoint is tried. When none is intact, ``CheckpointError`` lists what is wrong with each.

Both expect to be the only writer of the folder (``train.ppo`` holds the run folder's lock). The snapshots of a
policy (``best/``, ``last/``) are written the same way by either trainer (``save_snapshot``).
"""

from __future__ import annotations

import json
import os
import pickle
import random
import re
import shutil
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

__all__ = [
    "Checkpoint",
    "CheckpointError",
    "CheckpointWarning",
    "save_checkpoint",
    "write_checkpoint",
    "set_aside",
    "checkpoint_dirs",
    "load_checkpoint",
    "restore_rng",
    "write_json_atomic",
    "write_text_atomic",
    "file_mode",
    "save_snapshot",
    "copy_policy",
    "read_snapshot_info",
    "recover_snapshot",
]

_NAME = re.compile(r"\d{12}")  # a checkpoint folder: the step counter, zero-padded so names sort by steps
CORRUPT_SUFFIX = ".corrupt"


class CheckpointError(ValueError):
    """No checkpoint in the folder can be resumed from; the message names each one and what is wrong."""


class CheckpointWarning(UserWarning):
    """A checkpoint was unusable (the message names the file) and an older one is used instead."""


def file_mode(directory: bool = False) -> int:
    """The permissions a new file (0o666) or directory (0o777) gets under the umask; ``mkstemp`` and
    ``mkdtemp`` give 0o600 and 0o700, which would make the run's files private to their owner."""
    umask = os.umask(0)
    os.umask(umask)
    return (0o777 if directory else 0o666) & ~umask


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file next to it and ``os.replace``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_json_atomic(path: Path, data) -> None:
    """Write ``data`` as JSON to ``path`` through a temporary file and ``os.replace``."""
    write_text_atomic(path, json.dumps(data, indent=2) + "\n")


# ------------------------------------------------------------------ snapshots (best/, last/)


def _aside(path: Path) -> Path:
    """Where ``path`` waits while a new version replaces it (directories cannot be replaced in one rename)."""
    return path.with_name(f".{path.name}.old")


def recover_snapshot(path: Path) -> None:
    """Undo a replacement of the directory ``path`` that a killed process left half done: the old
    version, moved aside, goes back in place if nothing replaced it."""
    path, old = Path(path), _aside(Path(path))
    if old.exists():
        if path.exists():
            shutil.rmtree(old)
        else:
            os.replace(old, path)


def _replace_dir(tmp: Path, path: Path) -> None:
    """Rename the complete directory ``tmp`` to ``path``, replacing what is there."""
    old = _aside(path)
    if old.exists():
        shutil.rmtree(old)
    if path.exists():
        os.replace(path, old)
    os.replace(tmp, path)
    if old.exists():
        shutil.rmtree(old)


def save_snapshot(path: Path, write: Callable[[Path], None], info: dict) -> Path:
    """Write a policy through ``write(folder)`` (the trainer's files: ``model.zip`` and ``vecnormalize.pkl``, or an
    RLlib ``module/``) and ``info.json`` as the directory ``path``.

    The files are written into a temporary directory that then replaces ``path``, so ``path``
    never holds a model from one moment and statistics from another.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    recover_snapshot(path)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}."))
    try:
        write(tmp)
        write_json_atomic(tmp / "info.json", info)
        os.chmod(tmp, file_mode(directory=True))
        _replace_dir(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return path


def copy_policy(source: Path, target: Path, names: tuple[str, ...]) -> None:
    """Make the files (or folders) ``names`` of ``target`` those of ``source``, each replaced atomically; one that
    ``source`` lacks is removed from ``target``."""
    for name in names:
        src, dst = Path(source) / name, Path(target) / name
        if src.is_dir():
            tmp = Path(tempfile.mkdtemp(dir=dst.parent, prefix=f".{dst.name}."))
            try:
                shutil.copytree(src, tmp, dirs_exist_ok=True)
                os.chmod(tmp, file_mode(directory=True))
                _replace_dir(tmp, dst)
            finally:
                if tmp.exists():
                    shutil.rmtree(tmp, ignore_errors=True)
        elif src.is_file():
            fd, tmp = tempfile.mkstemp(dir=dst.parent, prefix=f".{dst.name}.", suffix=dst.suffix)
            os.close(fd)
            try:
                shutil.copyfile(src, tmp)
                os.chmod(tmp, file_mode())
                os.replace(tmp, dst)
            finally:
                if os.path.exists(tmp):
                    os.unlink(tmp)
        elif dst.is_dir():
            shutil.rmtree(dst)
        elif dst.exists():
            dst.unlink()


def read_snapshot_info(path: Path) -> dict | None:
    """The ``info.json`` of a snapshot directory, or None if there is no snapshot (a snapshot replaces its directory
    in one rename, so one with its ``info.json`` is complete)."""
    path = Path(path)
    if not (path / "info.json").is_file():
        return None
    return json.loads((path / "info.json").read_text())


# ------------------------------------------------------------------ checkpoints


def checkpoint_dirs(folder: Path) -> list[Path]:
    """The checkpoint directories under ``folder``, newest (most steps) first."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted((p for p in folder.iterdir() if p.is_dir() and _NAME.fullmatch(p.name)), reverse=True)


def write_checkpoint(folder: Path, steps: int, write: Callable[[Path], None], keep: int = 2) -> Path:
    """Write the checkpoint at ``steps`` env steps through ``write(tmp)`` into a hidden temporary folder under
    ``folder``, then rename it into place as ``<steps, 12 digits>``; returns its directory. Older checkpoints beyond
    the ``keep`` newest are deleted, and so are hidden leftovers of writes a killed process did not finish. Either
    trainer's checkpoints are written so (``train.rllib``'s hold an RLlib algorithm)."""
    if keep < 2:
        raise ValueError(f"keep must be >= 2 so that a corrupt checkpoint has an intact predecessor, got {keep}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = f"{int(steps):012d}"
    tmp = Path(tempfile.mkdtemp(dir=folder, prefix=f".{name}."))
    try:
        write(tmp)
        os.chmod(tmp, file_mode(directory=True))
        _replace_dir(tmp, folder / name)  # a second save at the same step count (Ctrl-C, the end) replaces the first
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    for old in checkpoint_dirs(folder)[keep:]:
        shutil.rmtree(old, ignore_errors=True)
    for leftover in folder.glob(".*"):  # temporary folders of saves that a kill interrupted
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
    return folder / name


def set_aside(path: Path) -> Path:
    """Move the unusable checkpoint ``path`` to ``<name>.corrupt`` (replacing an older one there), kept for
    inspection; returns where it went."""
    target = path.with_name(path.name + CORRUPT_SUFFIX)
    if target.exists():
        shutil.rmtree(target)
    os.replace(path, target)
    return target


def save_checkpoint(folder: Path, model, vec_normalize, progress: dict, keep: int = 2) -> Path:
    """Save a checkpoint of ``model`` and ``vec_normalize`` (None: the run does not normalise) under
    ``folder`` (``write_checkpoint``); returns its directory."""

    def write(tmp: Path) -> None:
        model.save(tmp / "model.zip")
        if vec_normalize is not None:
            vec_normalize.save(tmp / "vecnormalize.pkl")
        with open(tmp / "rng.pkl", "wb") as f:
            pickle.dump(
                {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}, f
            )
        write_json_atomic(tmp / "progress.json", {**progress, "num_timesteps": int(model.num_timesteps)})

    return write_checkpoint(folder, model.num_timesteps, write, keep)


@dataclass
class Checkpoint:
    """A checkpoint read back: the model and statistics without an env (attach one with
    ``vec_normalize.set_venv`` and ``model.set_env``), the progress record and the generator states."""

    path: Path
    model: object
    vec_normalize: object | None
    progress: dict
    rng: dict


class _Unusable(Exception):
    """Why a checkpoint cannot be resumed from; the message names the file."""


def _read(path: Path, reader):
    if not path.is_file():
        raise _Unusable(f"{path} is missing")
    try:
        return reader(path)
    except Exception as e:  # truncated or garbage files raise from pickle, json, zipfile, torch...
        raise _Unusable(f"cannot read {path}: {type(e).__name__}: {e}") from e


def _load_pickle(path: Path):
    with open(path, "rb") as f:
        return pickle.load(f)


def _read_checkpoint(path: Path, normalize: bool, algo, load_kwargs: dict) -> Checkpoint:
    from stable_baselines3.common.vec_env import VecNormalize

    progress = _read(path / "progress.json", lambda p: json.loads(p.read_text()))
    if not isinstance(progress, dict) or not isinstance(progress.get("num_timesteps"), int):
        raise _Unusable(f"{path / 'progress.json'} has no step count")
    rng = _read(path / "rng.pkl", _load_pickle)
    if not isinstance(rng, dict) or not {"python", "numpy", "torch"} <= set(rng):
        raise _Unusable(f"{path / 'rng.pkl'} does not hold the Python, NumPy and torch generator states")
    stats_file = path / "vecnormalize.pkl"
    vec_normalize = None
    if normalize:
        if not stats_file.is_file():
            raise _Unusable(
                f"{stats_file} is missing, but the run normalises (config.yaml: normalize); "
                "resuming without it would silently train without normalisation"
            )
        vec_normalize = _read(stats_file, _load_pickle)
        if not isinstance(vec_normalize, VecNormalize):
            raise _Unusable(f"{stats_file} does not hold VecNormalize statistics (got {type(vec_normalize).__name__})")
    elif stats_file.exists():
        raise _Unusable(f"{stats_file} exists, but the run does not normalise (config.yaml: normalize: false)")
    model = _read(path / "model.zip", lambda p: algo.load(p, device="cpu", **load_kwargs))
    if model.num_timesteps != progress["num_timesteps"]:
        raise _Unusable(
            f"{path / 'model.zip'} is at {model.num_timesteps} steps, {path / 'progress.json'} at {progress['num_timesteps']}"
        )
    if vec_normalize is not None and vec_normalize.observation_space.shape != model.observation_space.shape:
        raise _Unusable(f"{stats_file} has statistics for observations of another shape than the model's")
    return Checkpoint(path, model, vec_normalize, progress, rng)


def load_checkpoint(folder: Path, normalize: bool, algo=None, **load_kwargs) -> Checkpoint:
    """The newest intact checkpoint under ``folder``; unusable newer ones are moved aside with a warning.

    Args:
        folder: the run's ``checkpoints/``.
        normalize: whether the run normalises, i.e. whether a checkpoint must hold ``vecnormalize.pkl``.
        algo: the SB3 algorithm class (default PPO).
        load_kwargs: passed to ``algo.load`` (``tensorboard_log``, ``verbose``...).

    Raises:
        CheckpointError: no checkpoint, or none intact; the message names every file at fault.
    """
    if algo is None:
        from stable_baselines3 import PPO as algo
    folder = Path(folder)
    candidates = checkpoint_dirs(folder)
    if not candidates:
        raise CheckpointError(f"no checkpoint in {folder}")
    rejected = []
    for path in candidates:
        try:
            checkpoint = _read_checkpoint(path, normalize, algo, load_kwargs)
        except _Unusable as e:
            rejected.append((path, str(e)))
            continue
        for bad, why in rejected:
            target = set_aside(bad)
            warnings.warn(
                f"checkpoint unusable: {why}; moved it to {target} and resumed from the previous checkpoint, {path}",
                CheckpointWarning,
                stacklevel=2,
            )
        return checkpoint
    reasons = "; ".join(why for _, why in rejected)
    raise CheckpointError(f"no intact checkpoint in {folder}: {reasons}")


def restore_rng(state: dict) -> None:
    """Restore the Python, NumPy and torch generator states saved with a checkpoint."""
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"])
