"""fov_marl.training."""
