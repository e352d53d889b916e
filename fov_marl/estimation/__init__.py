"""fov_marl.estimation."""
