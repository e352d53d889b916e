"""fov_marl.baselines."""
