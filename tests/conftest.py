"""Shared test set-up: one thread per pool (torch and the vector env share 2 cores), headless rendering, and the
``sb3`` mark on every test of ``tests/sb3/``."""
import os
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

try:
    import torch  # noqa: E402

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover - torch is a test dependency
    pass

from leg_env.physics.params import LegParams  # noqa: E402

SB3_FOLDER = Path(__file__).resolve().parent / "sb3"


def pytest_collection_modifyitems(config, items):
    """Mark ``sb3`` every test of ``tests/sb3/`` (the modules that need the training stack throughout), so that
    ``-m "not sb3"`` selects the suite that runs without Stable-Baselines3 (pyproject's markers)."""
    for item in items:
        if SB3_FOLDER in item.path.resolve().parents:
            item.add_marker(pytest.mark.sb3)


@pytest.fixture
def params() -> LegParams:
    """The lesson's default parameters."""
    return LegParams()


def random_params(rng: np.random.Generator) -> LegParams:
    """A random but physically valid parameter set (COM offsets inside their links)."""
    l1, l2 = rng.uniform(0.2, 1.0, size=2)
    return LegParams(
        m_b=rng.uniform(2.0, 20.0),
        m1=rng.uniform(0.5, 5.0),
        m2=rng.uniform(0.5, 5.0),
        I_b=rng.uniform(0.1, 2.0),
        I1=rng.uniform(0.01, 0.5),
        I2=rng.uniform(0.01, 0.5),
        l1=l1,
        l2=l2,
        c1=rng.uniform(0.1, 0.9) * l1,
        c2=rng.uniform(0.1, 0.9) * l2,
        g=rng.uniform(1.0, 20.0),
    )
