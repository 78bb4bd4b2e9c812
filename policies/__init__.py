"""Controllers for the leg-env tasks with Stable-Baselines3's ``predict`` interface, and the shipped policies.

The model-based controllers: ``policies.lqr.LQRController`` (balancing; stateless), ``policies.hopper.HopperController``
(hopping), ``policies.gated.GatedController`` (a backward hop before the LQR for the unilateral balance task's
starts that need one), ``policies.stepping.SteppingController`` (the LQR, and a quick hop after a large push), and
the model-predictive controllers ``policies.mpc.HopMPC`` and ``policies.push_mpc.PushMPC`` (iLQR on the step's exact
Jacobians around the hopper and the stepping controller, ``policies.ilqr``). The stateful ones share ``policies.base.BatchedController``: one ``predict`` for one observation or a batch, the
per-robot state, SB3's ``episode_start``; all read the observation by the task's named columns
(``leg_env.tasks.base.Obs``).

The shipped PPO policies are folders, each with its card (``README.md``), all plain PPO from scratch: ``ppo_stance``
(the pinned balance), ``ppo_balance``, ``ppo_push_v2``, ``ppo_push_randomized`` (trained on randomised robots) and
``ppo_hop_v4``. Load any of them with ``train.evaluate.load_policy``.
"""
