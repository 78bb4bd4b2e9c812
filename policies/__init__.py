"""Controllers for the leg-env tasks with Stable-Baselines3's ``predict`` interface.

``policies.lqr.LQRController`` is the model-based reference for balancing, ``policies.hopper.HopperController``
for hopping, and ``policies.gated.GatedController`` adds a backward hop to the LQR for the unilateral balance
task's starts that need one. The shipped PPO policies are folders (``policies/ppo_stance/``,
``policies/ppo_stance_randomized/``, ``policies/ppo_stance_v1/``, ``policies/ppo_hop/``); load them with ``train.evaluate.load_policy``.
"""
