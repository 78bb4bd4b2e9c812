"""Gait stability (``train.stability``) of the model-based controllers: the float64 closed loop is the env's, a held
hopper's periodic gait closes and its Floquet multipliers are the differenced map's, the MPC's step derivative with its
line search's choice held, and the Lyapunov exponents are those of maps whose answer is known. The PPO policy's loop
is in ``tests/sb3/test_stability_policy.py``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from train.policy_loading import load_policy
from train.stability import (HopLoop, analyse, hop_maps, lyapunov_exponents, main, map_error, period_map,
                             periodic_orbit)

POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_hop_v4"


def loop_against_env(controller: str, policy, steps: int) -> tuple[float, bool]:
    """Run the loop and the env side by side under ``policy`` (the env's controller or policy): the largest gap between
    their observations (relative, at least absolute), and whether the robot flew. Fails if the actions differ or the
    episode ends."""
    loop = HopLoop(controller, 0.10)
    z, d = loop.start(0)
    obs, _ = loop.env.reset(seed=0)
    if hasattr(policy, "reset"):
        policy.reset()
    worst, flew = 0.0, False
    for _ in range(steps):
        worst = max(worst, float(np.max(np.abs(loop.observe(z, d)[0] - obs) / np.maximum(1.0, np.abs(obs)))))
        action, _ = policy.predict(obs)
        z, d, u, _ = loop.step(z, d)
        assert np.abs(u[0] - action).max() < 1e-4
        obs, _, terminated, _, _ = loop.env.step(action)
        assert not terminated
        flew |= obs[15] == 0.0  # the contact flag
    return worst, flew


@pytest.mark.parametrize("controller, steps", [("hopper", 300), ("mpc", 25)])
def test_the_loop_is_the_env(controller, steps):
    """The loop's observation is the env's (rounded to float32) along the controller's own episode."""
    worst, flew = loop_against_env(controller, load_policy(controller, env_id="leg_env/PlanarLegHop-v4"), steps)
    assert worst < 1e-5
    assert flew or controller == "mpc"  # the MPC's 25 steps are its first crouch


def test_a_held_hoppers_gait_is_periodic_and_its_multipliers_are_the_differenced_maps():
    r = analyse("hopper", 0.08, seed=0, settle=10.0, hops=6, settings=dict(apex_gain=0.0))
    assert not r.fell and r.defined
    assert r.locked == 1 and r.closure <= 1e-9
    assert r.neutral == ("x_b", "bias")  # the hopper does not observe its position; its apex bias is held
    assert r.fd_error <= 1e-6
    assert np.abs(r.multipliers - r.multipliers_fd).max() <= 1e-5
    assert 0.5 < np.abs(r.multipliers[0]) < 1.0  # stable, and not trivially
    assert r.exponents[0] < 0.0
    assert abs(np.log(r.perturbation_growth) - r.exponents[0]) < 0.1  # simulation alone agrees
    assert r.jump_share == 0.0


def test_newtons_orbit_returns_to_itself():
    """The orbit Newton's method finds, run by the loop's plain step (no Jacobian), comes back to itself."""
    loop = HopLoop("hopper", 0.08, settings=dict(apex_gain=0.0))
    found, _ = hop_maps(loop, seed=0, settle=8.0, hops=2)
    h = found[-1]
    z, closure, DP, defined, _ = periodic_orbit(loop, h.z, h.d, h.steps)
    assert defined and closure <= 1e-10
    end, d = z.copy(), {k: v.copy() for k, v in h.d.items()}
    for _ in range(h.steps):
        end, d, _, _ = loop.step(end, d)
    live = np.isfinite(z[0])
    live[0] = False  # x_b: the gait may walk
    assert np.abs(end[0, live] - z[0, live]).max() <= 1e-10
    end_composed, DP2, _, _ = period_map(loop, z, h.d, h.steps)
    assert np.array_equal(end_composed, end)  # the composed map steps the same loop
    assert np.allclose(DP2, DP, rtol=0, atol=1e-6 * np.abs(DP).max())


def test_lyapunov_exponents_of_known_maps():
    rng = np.random.default_rng(0)
    D = np.diag([2.0, 0.5, 0.0])
    e = lyapunov_exponents([D] * 30)
    assert np.allclose(e[:2], np.log([2.0, 0.5])) and e[2] == -np.inf
    # a periodic sequence of non-normal maps: the exponents are those of the period's product, per map
    maps = [np.eye(3) + rng.normal(scale=0.8, size=(3, 3)) for _ in range(3)]
    P = maps[2] @ maps[1] @ maps[0]
    w = np.sort(np.log(np.abs(np.linalg.eigvals(P))))[::-1] / 3
    e = lyapunov_exponents(maps * 200, warmup=30)
    if len(set(np.round(np.abs(np.linalg.eigvals(P)), 6))) == 3:  # distinct moduli: the exponents are the eigenvalues'
        assert np.allclose(e, w, atol=2e-3)
    assert abs(e.sum() - np.log(abs(np.linalg.det(P))) / 3) < 1e-9  # the volume's growth, exactly


def test_bad_input_is_refused():
    with pytest.raises(TypeError, match="settings"):
        HopLoop(str(POLICY), 0.10, settings=dict(apex_gain=0.0))
    with pytest.raises(TypeError):
        HopLoop("hopper", 0.10, settings=dict(no_such_gain=1.0))
    with pytest.raises(ValueError, match="key=value"):
        main(["hopper:apex_gain", "--commands", "0.08"])


def test_the_mpcs_step_derivative_holds_its_line_search_choice():
    """The MPC loop's one-step derivative against centred differences of the loop's step with the line search's
    choice held, where its law does not jump; the choice held is the one the MPC made."""
    loop = HopLoop("mpc", 0.10)
    z, d = loop.start(0)
    smooth = 0
    for k in range(46):
        if k in (20, 45):  # crouching, pushing
            jumps = loop.jumps
            z_new, d_new, G, ok = loop.jacobian(z, d)
            choice = loop.choice
            assert ok and choice in (-1, 0, 1, 2)
            z_again, _, _, _ = loop.step(z, d, hold=choice)
            assert np.array_equal(z_again, z_new, equal_nan=True)
            if loop.jumps == jumps:
                error, _ = map_error(loop, G, z, d, 1, choices=(choice,))
                assert error <= 1e-6
                smooth += 1
            z, d = z_new, d_new
        else:
            z, d, _, _ = loop.step(z, d)
    assert smooth >= 1


def test_results_round_trip_through_their_json(tmp_path):
    """``--merge`` rewrites the table and the plot from earlier runs' JSON files: the same rows, in the order given."""
    from train.stability import Stability, write_results

    def row(name, locked):
        w = np.array([0.7 + 0.1j, 0.7 - 0.1j, 0.3]) if locked else np.zeros(0)
        return Stability(name, 0.08, (65, 65), np.array([-0.35, -0.4, -np.inf]), locked, 1e-12 if locked else np.nan, w,
                         w + 1e-8, 3e-9, True, False, ("x_b",), 0.0, 0.7, 0.69)

    run = dict(seconds=1.0, seed=0, settle=10.0, hops=30, machine="test", date="2026-01-01")
    write_results([row("a", 1)], tmp_path / "a", run)
    write_results([row("b", 0)], tmp_path / "b", run)
    assert main(["x", "--merge", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--out", str(tmp_path / "m")]) == 0
    table = (tmp_path / "m.md").read_text()
    assert table.index("| a |") < table.index("| b |") and "0.700 +- 0.100i, 0.300" in table and "in 2 s" in table
    assert (tmp_path / "m.png").stat().st_size > 0
    import json

    rows = json.loads((tmp_path / "m.json").read_text())["results"]
    assert [r["controller"] for r in rows] == ["a", "b"] and rows[0]["multipliers"][0] == [0.7, 0.1]
