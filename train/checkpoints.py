"""Atomic training checkpoints: model, normalisation statistics, progress and random generator states.

Layout under ``<run>/checkpoints/``::

    <num_timesteps>/model.zip          the PPO model (policy, optimiser, step counter)
    <num_timesteps>/vecnormalize.pkl   observation/return statistics
    <num_timesteps>/progress.json      steps, wall time, evaluation history, resume count
    <num_timesteps>/rng.pkl            Python, NumPy and torch generator states
    latest.json                        {"dir": "<num_timesteps>"}: the newest complete checkpoint

A checkpoint is written into a temporary folder, renamed into place, and only then does
``latest.json`` (itself replaced atomically) point at it; a process killed at any moment leaves
the previous checkpoint intact. The ``keep`` newest checkpoints are kept.
"""

from __future__ import annotations

import json
import os
import pickle
import random
import shutil
import tempfile
from pathlib import Path

import numpy as np
import torch

__all__ = [
    "save_checkpoint",
    "latest_checkpoint",
    "load_progress",
    "restore_rng",
    "write_json_atomic",
    "file_mode",
    "save_snapshot",
    "read_snapshot_info",
]

LATEST = "latest.json"


def file_mode(directory: bool = False) -> int:
    """The permissions a new file (0o666) or directory (0o777) gets under the umask; ``mkstemp`` and
    ``mkdtemp`` give 0o600 and 0o700, which would make the run's files private to their owner."""
    umask = os.umask(0)
    os.umask(umask)
    return (0o777 if directory else 0o666) & ~umask


def write_json_atomic(path: Path, data) -> None:
    """Write ``data`` as JSON to ``path`` through a temporary file and ``os.replace``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(data, f, indent=2)
        f.write("\n")
    os.chmod(tmp, file_mode())
    os.replace(tmp, path)


def save_snapshot(path: Path, model, vec_normalize, info: dict) -> Path:
    """Write ``model.zip``, ``vecnormalize.pkl`` (if any) and ``info.json`` as the directory ``path``.

    The files are written into a temporary directory that then replaces ``path``, so ``path``
    never holds a model from one moment and statistics from another.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}."))
    old = path.with_name(f".{path.name}.old")
    try:
        model.save(tmp / "model.zip")
        if vec_normalize is not None:
            vec_normalize.save(tmp / "vecnormalize.pkl")
        write_json_atomic(tmp / "info.json", info)
        os.chmod(tmp, file_mode(directory=True))
        if old.exists():
            shutil.rmtree(old)
        if path.exists():
            os.replace(path, old)
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, old):
            if leftover.exists():
                shutil.rmtree(leftover, ignore_errors=True)
    return path


def read_snapshot_info(path: Path) -> dict | None:
    """The ``info.json`` of a snapshot directory, or None if there is no complete snapshot."""
    path = Path(path)
    if not (path / "model.zip").is_file() or not (path / "info.json").is_file():
        return None
    return json.loads((path / "info.json").read_text())


def save_checkpoint(folder: Path, model, vec_normalize, progress: dict, keep: int = 2) -> Path:
    """Save a checkpoint of ``model`` and ``vec_normalize`` under ``folder``; returns its directory."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = f"{model.num_timesteps:012d}"
    final = folder / name
    tmp = Path(tempfile.mkdtemp(dir=folder, prefix=f".{name}."))
    try:
        model.save(tmp / "model.zip")
        vec_normalize.save(tmp / "vecnormalize.pkl")
        with open(tmp / "rng.pkl", "wb") as f:
            pickle.dump(
                {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}, f
            )
        write_json_atomic(tmp / "progress.json", {**progress, "num_timesteps": int(model.num_timesteps)})
        if final.exists():
            shutil.rmtree(final)
        os.chmod(tmp, file_mode(directory=True))
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    write_json_atomic(folder / LATEST, {"dir": name})
    for old in sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))[:-keep]:
        if old.name != name:
            shutil.rmtree(old, ignore_errors=True)
    return final


def latest_checkpoint(folder: Path) -> Path | None:
    """The newest complete checkpoint directory under ``folder``, or None."""
    pointer = Path(folder) / LATEST
    if not pointer.is_file():
        return None
    try:
        path = Path(folder) / json.loads(pointer.read_text())["dir"]
    except (ValueError, KeyError) as e:
        raise ValueError(f"corrupt checkpoint pointer {pointer}: {e}") from e
    if not (path / "model.zip").is_file():
        raise FileNotFoundError(f"{pointer} points at {path}, which has no model.zip")
    return path


def load_progress(checkpoint: Path) -> dict:
    """The ``progress.json`` of a checkpoint directory."""
    return json.loads((Path(checkpoint) / "progress.json").read_text())


def restore_rng(checkpoint: Path) -> None:
    """Restore the Python, NumPy and torch generator states saved with a checkpoint (if present)."""
    path = Path(checkpoint) / "rng.pkl"
    if not path.is_file():
        return
    with open(path, "rb") as f:
        state = pickle.load(f)
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])
    torch.set_rng_state(state["torch"])
