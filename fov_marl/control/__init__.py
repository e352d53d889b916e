"""fov_marl.control: the paper's controller (Section VI) and desired inputs (VII-A, VII-D).

Entry points::

    from fov_marl.control import FovCbfController, ControllerParams
    controller = FovCbfController(config, ControllerParams())
    res = controller.solve(u_star, p_body, v_est_body, d, ids)   # res.u: [vx, vy, ω]

    from fov_marl.control import coverage_desired_input, crossing_desired_input
    u_star = coverage_desired_input(pose_world, mean_body, config, params).u_star

All inputs and outputs are body-frame velocities (m/s, rad/s); convert to the env's
normalised actions with :func:`fov_marl.spaces.velocity_to_action`.

Modules: :mod:`~fov_marl.control.params` (knobs), :mod:`~fov_marl.control.cbf`
(Eq. 11-12, 16-17), :mod:`~fov_marl.control.qp` (Eq. 18-19),
:mod:`~fov_marl.control.controller` (pipeline), :mod:`~fov_marl.control.coverage`
(Lloyd, crossing), :mod:`~fov_marl.control.benchmark`.
"""

from fov_marl.control.cbf import (
    ROW_NAMES,
    SAFETY_ROW,
    CbfRows,
    cbf_rows,
    class_k,
    fov_barrier,
    fov_barrier_lie,
    normalise_rows,
    row_authority,
    row_h_max,
    slack,
)
from fov_marl.control.controller import ControlResult, FovCbfController
from fov_marl.control.coverage import (
    DesiredInput,
    coverage_centroid_reference,
    coverage_centroids,
    coverage_desired_input,
    coverage_desired_inputs,
    crossing_desired_input,
    facing_omega,
    proportional_input,
)
from fov_marl.control.params import ControllerParams
from fov_marl.control.qp import HierarchicalQP, QPResult, least_distance, project_to_admissible

__all__ = [
    "ROW_NAMES",
    "SAFETY_ROW",
    "CbfRows",
    "ControlResult",
    "ControllerParams",
    "DesiredInput",
    "FovCbfController",
    "HierarchicalQP",
    "QPResult",
    "cbf_rows",
    "class_k",
    "coverage_centroid_reference",
    "coverage_centroids",
    "coverage_desired_input",
    "coverage_desired_inputs",
    "crossing_desired_input",
    "facing_omega",
    "fov_barrier",
    "fov_barrier_lie",
    "least_distance",
    "normalise_rows",
    "project_to_admissible",
    "proportional_input",
    "row_authority",
    "row_h_max",
    "slack",
]
