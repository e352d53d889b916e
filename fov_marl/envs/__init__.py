"""fov_marl.envs."""
