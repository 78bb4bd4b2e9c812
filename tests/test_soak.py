"""The soak in CI: 10^5 env-steps per case and action kind (``benchmarks/soak.py``).

The script runs 10^7 per combination at N = 4096; this runs the same function, smaller.
"""

import importlib.util
from pathlib import Path

import pytest

SOAK_STEPS = 100_000
NUM_ENVS = 500
_spec = importlib.util.spec_from_file_location("soak", Path(__file__).resolve().parents[1] / "benchmarks" / "soak.py")
soak = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(soak)


@pytest.mark.parametrize("actions", soak.ACTIONS)
@pytest.mark.parametrize("case", list(soak.CASES))
def test_soak_reports_nothing_wrong(case, actions):
    r = soak.soak(case, actions, SOAK_STEPS, num_envs=NUM_ENVS, seed=13)
    assert r["steps"] >= SOAK_STEPS
    assert (r["non_finite"], r["exceptions"], r["unflagged"]) == (0, 0, 0), r
    assert r["terminated"] > 100  # ten times the torque limit: the robots fall, and are reset, all the time
