"""Training and evaluation: ``train.ppo`` (PPO with SB3), ``train.evaluate`` (metrics, GIF, plots)."""
