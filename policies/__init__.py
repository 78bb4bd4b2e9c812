"""Controllers for ``leg_env/PlanarLegStance-v0`` with Stable-Baselines3's ``predict`` interface.

``policies.lqr.LQRController`` is the model-based reference; ``policies/ppo_stance/`` holds the PPO
policy trained by the default configuration (load it with ``train.evaluate.load_policy``).
"""
