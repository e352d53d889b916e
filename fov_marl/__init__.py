"""fov_marl."""
