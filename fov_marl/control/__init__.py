"""fov_marl.control."""
