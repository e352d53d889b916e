"""fov_marl.wrappers."""
