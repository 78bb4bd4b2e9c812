"""Gait stability (``train.stability``) of the shipped PPO hop policy: its float64 closed loop is the env's, its hop
maps (its network's derivative from torch, the step's exact ``A`` and ``B``, the observation's memories) are their
centred differences, and its gait is chaotic by the maps and by simulation alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from test_stability import loop_against_env
from train.policy_loading import load_policy
from train.stability import HopLoop, analyse, hop_maps, map_error, return_map_fd

POLICY = Path(__file__).resolve().parents[2] / "policies" / "ppo_hop_v4"


def test_the_loop_is_the_env():
    """The loop's observation is the env's (rounded to float32) along the policy's own episode; its gait amplifies
    the float32 rounding, so the horizon is 100 steps."""
    worst, flew = loop_against_env(str(POLICY), load_policy(POLICY), 100)
    assert worst < 1e-4 and flew


def test_the_policys_hop_maps_are_their_differences():
    """The PPO policy's hop maps (its network's derivative from torch, the step's exact A and B, the observation's
    memories) against centred differences of the loop over each hop."""
    loop = HopLoop(str(POLICY), 0.10)
    found, fell = hop_maps(loop, seed=0, settle=2.0, hops=3)
    assert not fell and len(found) == 3
    for h in found:
        assert h.defined
        error, H_fd = map_error(loop, h.H, h.z, h.d, h.steps)
        assert error <= 1e-6
        assert np.abs(h.H).max() > 1.0  # not trivially small
        assert np.abs(h.H - return_map_fd(loop, h.z, h.d, h.steps, 1e-7)).max() <= 1e-6 * np.abs(h.H).max()


def test_the_policys_gait_is_chaotic_by_its_maps_and_by_simulation():
    """The PPO policy's hops never repeat: neighbouring gaits diverge, by the composed maps' Lyapunov exponent and by
    perturbations simulated alone, which agree."""
    r = analyse(str(POLICY), 0.10, seed=0, settle=3.0, hops=15)
    assert not r.fell and r.locked == 0 and len(set(r.hop_steps)) > 2
    assert r.fd_error <= 1e-6
    assert r.exponents[0] > np.log(1.5) and r.perturbation_growth > 1.5
    assert abs(np.log(r.perturbation_growth) - r.exponents[0]) < 0.3


def test_a_missing_policy_is_refused():
    with pytest.raises(FileNotFoundError):
        HopLoop("no/such/policy", 0.10)
