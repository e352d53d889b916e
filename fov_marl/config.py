"""Scenario configuration: frozen dataclasses with the paper's values as defaults.

Every keyword accepted by ``fov_coverage_v0.parallel_env(...)`` and
``fov_crossing_v0.parallel_env(...)`` is a field of :class:`ScenarioConfig`.
Unknown keywords and out-of-range values raise :class:`ConfigError` (a
``ValueError``) naming the field and the allowed range.

Paper parameters (Section VII) and the choices the paper leaves open
====================================================================

=========================  =====================  ==========================================
field                      default                source / reason
=========================  =====================  ==========================================
``n_agents``               6 (crossing: 4)        paper VII-B, VII-D
``arena_size_m``           40.0                   40 m x 40 m arena Q = [0, 40]^2
``fov_deg``                120.0                  camera amplitude beta; 360 = ideal case
``detection_range_m``      10.0                   R_d
``sensing_radius_m``       6.0                    R_s, isotropic coverage sensor
``safety_distance_m``      2.0                    D_s, hard CBF row (Eq. 12, row 3)
``robot_radius_m``         0.5                    collision when centres < 2 radii = 1 m
``v_max_mps``              1.0                    max planar speed (norm)
``omega_max_radps``        1.5                    authors' code clip
``meas_cov_diag``          (0.1, 0.1, 0.5)        Sigma_MEAS read as a covariance
                                                  (m^2, m^2, rad^2): std 0.32 m, 0.71 rad
``meas_noise_clip_sigma``  5.0                    noise truncated at 5 std so observations
                                                  stay inside their Box (p < 6e-7 per draw)
``density_mean_m``         (20.0, 20.0)           q_m, the centre of the arena
``density_sigma_m``        2.8                    isotropic Gaussian phi(q)
``dt_s``                   0.2                    authors' control period 0.2-0.25 s
``max_cycles``             1000                   200 s of simulated time
=========================  =====================  ==========================================

Density choice (``density_sigma_m = 2.8``, q_m at the centre): a single sensing
disk of radius 6 m centred on q_m captures ``1 - exp(-36 / (2 * 2.8**2)) = 0.899``
of the mass (η ≈ 0.90 for one robot alone at its best), while six disks can cover
a disk of radius 6 / 0.5559 = 10.8 m (optimal 6-disk covering), which holds
``1 - exp(-10.8**2 / 15.68) = 0.9994`` of the mass, so six robots in a good
configuration reach η ≥ 0.999. The horizon of 1000 steps x 0.2 s = 200 s lets a
robot starting in a corner (28 m from q_m) arrive at 1 m/s with time to settle.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from fov_marl.validation import ConfigError, check_int, check_real

__all__ = ["ConfigError", "ScenarioConfig", "make_config"]

Scenario = Literal["coverage", "crossing"]


_check_range = check_real
_check_int = check_int


@dataclass(frozen=True)
class ScenarioConfig:
    """All parameters of one scenario; frozen and validated on construction.

    Units are SI (metres, seconds, radians) except ``fov_deg`` (degrees, the one
    user-facing angle). See the module docstring for the source of each default.

    Attributes:
        scenario: ``"coverage"`` (paper VII-A/B/C) or ``"crossing"`` (VII-D).
        n_agents: number of robots N, in [1, 256].
        arena_size_m: side L of the square arena Q = [0, L]^2, in [5, 1000] m.
        fov_deg: camera amplitude beta, in (0, 360] degrees; the sector is centred
            on the body x axis and turns with the robot's yaw.
        detection_range_m: camera range R_d, in (0, inf) m.
        sensing_radius_m: coverage sensing radius R_s, in (0, inf) m.
        safety_distance_m: D_s, in (0, inf) m; must exceed ``2 * robot_radius_m``.
        robot_radius_m: physical radius; two robots collide when their centres are
            closer than ``2 * robot_radius_m``. In (0, inf) m.
        v_max_mps: maximum planar speed, in (0, inf) m/s.
        omega_max_radps: maximum yaw rate, in (0, inf) rad/s.
        meas_cov_diag: diagonal of Sigma_MEAS for (x m^2, y m^2, theta rad^2), each
            in [0, inf); 0 gives noiseless measurements.
        meas_noise_clip_sigma: measurement noise is truncated at this many standard
            deviations (so observations stay inside their Box), in [1, inf).
        density_mean_m: q_m, world (x, y) m, inside the arena.
        density_sigma_m: standard deviation of the Gaussian phi(q), in (0, inf) m.
        dt_s: control period and integration step, in (0, 5] s.
        max_cycles: steps before truncation, in [1, inf).
        initial_poses: optional (N, 3) world [x m, y m, yaw rad]; inside the arena
            (at least one robot radius from each wall), no two robots closer than
            two radii. ``None`` draws them from the seeded generator.
        init_min_separation_m: minimum pairwise distance of random start
            positions, in [2 * robot_radius_m, inf) m.
        crossing_radius_m: crossing scenario: starts and targets lie on a circle
            of this radius around the arena centre, in (0, L/2 - robot_radius_m].
        crossing_jitter_m: crossing scenario: uniform jitter of starts and
            targets, in [0, inf) m.
        target_tolerance_m: crossing: a robot has arrived when closer than this to
            its target, in (0, inf) m.
        eta_grid_m: quadrature cell size for the coverage efficiency, in (0, 1] m.
        reward_eta_gain: coverage reward per unit gain of eta, in [0, inf).
        progress_gain: crossing reward per metre of progress, in [0, inf).
        arrival_bonus: crossing reward the first step a robot is within tolerance.
        collision_penalty: reward subtracted per collision a robot is part of, [0, inf).
        safety_penalty: reward subtracted per D_s violation a robot is part of, [0, inf).
    """

    scenario: Scenario = "coverage"
    n_agents: int = 6
    arena_size_m: float = 40.0
    fov_deg: float = 120.0
    detection_range_m: float = 10.0
    sensing_radius_m: float = 6.0
    safety_distance_m: float = 2.0
    robot_radius_m: float = 0.5
    v_max_mps: float = 1.0
    omega_max_radps: float = 1.5
    meas_cov_diag: tuple[float, float, float] = (0.1, 0.1, 0.5)
    meas_noise_clip_sigma: float = 5.0
    density_mean_m: tuple[float, float] = (20.0, 20.0)
    density_sigma_m: float = 2.8
    dt_s: float = 0.2
    max_cycles: int = 1000
    initial_poses: np.ndarray | None = field(default=None, compare=False)
    init_min_separation_m: float = 3.0
    crossing_radius_m: float = 12.0
    crossing_jitter_m: float = 0.5
    target_tolerance_m: float = 0.5
    eta_grid_m: float = 0.1
    reward_eta_gain: float = 100.0
    progress_gain: float = 1.0
    arrival_bonus: float = 10.0
    collision_penalty: float = 10.0
    safety_penalty: float = 1.0

    def __post_init__(self) -> None:
        if self.scenario not in ("coverage", "crossing"):
            raise ConfigError(
                f"scenario must be one of ('coverage', 'crossing'), got {self.scenario!r}"
            )
        _check_int("n_agents", self.n_agents, 1, 256)
        _check_int("max_cycles", self.max_cycles, 1)
        _check_range("arena_size_m", self.arena_size_m, 5.0, 1000.0)
        _check_range("fov_deg", self.fov_deg, 0.0, 360.0, lo_open=True)
        for name in (
            "detection_range_m",
            "sensing_radius_m",
            "safety_distance_m",
            "robot_radius_m",
            "v_max_mps",
            "omega_max_radps",
            "density_sigma_m",
            "target_tolerance_m",
        ):
            _check_range(name, getattr(self, name), 0.0, None, lo_open=True)
        _check_range("dt_s", self.dt_s, 0.0, 5.0, lo_open=True)
        _check_range("eta_grid_m", self.eta_grid_m, 0.0, 1.0, lo_open=True)
        _check_range("meas_noise_clip_sigma", self.meas_noise_clip_sigma, 1.0, None)
        for name in (
            "crossing_jitter_m",
            "reward_eta_gain",
            "progress_gain",
            "arrival_bonus",
            "collision_penalty",
            "safety_penalty",
        ):
            _check_range(name, getattr(self, name), 0.0, None)

        r = float(self.robot_radius_m)
        L = float(self.arena_size_m)
        if r >= L / 4:
            raise ConfigError(f"robot_radius_m must be in (0, arena_size_m/4 = {L / 4}), got {r}")
        if self.safety_distance_m <= 2 * r:
            raise ConfigError(
                f"safety_distance_m must be in (2 * robot_radius_m = {2 * r}, inf), "
                f"got {self.safety_distance_m}"
            )
        _check_range("init_min_separation_m", self.init_min_separation_m, 2 * r, None)
        _check_range("crossing_radius_m", self.crossing_radius_m, 0.0, L / 2 - r, lo_open=True)

        cov = _as_float_tuple("meas_cov_diag", self.meas_cov_diag, 3)
        for k, c in zip(("x", "y", "theta"), cov, strict=True):
            _check_range(f"meas_cov_diag[{k}]", c, 0.0, None)
        object.__setattr__(self, "meas_cov_diag", cov)

        qm = _as_float_tuple("density_mean_m", self.density_mean_m, 2)
        for k, c in zip(("x", "y"), qm, strict=True):
            _check_range(f"density_mean_m[{k}]", c, 0.0, L)
        object.__setattr__(self, "density_mean_m", qm)

        if self.initial_poses is not None:
            object.__setattr__(self, "initial_poses", self._validated_poses(self.initial_poses))

    # ------------------------------------------------------------------ derived
    @property
    def fov_rad(self) -> float:
        """Camera amplitude beta in radians."""
        return math.radians(self.fov_deg)

    @property
    def collision_distance_m(self) -> float:
        """Centre distance below which two robots collide (two radii)."""
        return 2.0 * self.robot_radius_m

    @property
    def meas_std(self) -> np.ndarray:
        """(3,) measurement noise standard deviations (m, m, rad)."""
        return np.sqrt(np.asarray(self.meas_cov_diag, dtype=np.float64))

    @property
    def isotropic(self) -> bool:
        """True when the camera sees all around (beta = 360 deg)."""
        return self.fov_deg >= 360.0

    def replace(self, **changes: Any) -> ScenarioConfig:
        """Return a validated copy with ``changes`` applied."""
        return make_config(base=self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict of every field (arrays become nested lists)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else v
        out["meas_cov_diag"] = list(self.meas_cov_diag)
        out["density_mean_m"] = list(self.density_mean_m)
        return out

    def _validated_poses(self, poses: Any) -> np.ndarray:
        try:
            arr = np.array(poses, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(
                f"initial_poses must be an array of shape ({self.n_agents}, 3), got {poses!r}"
            ) from None
        if arr.shape != (self.n_agents, 3):
            raise ConfigError(
                f"initial_poses must have shape (n_agents, 3) = ({self.n_agents}, 3) "
                f"[x m, y m, yaw rad], got shape {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ConfigError("initial_poses must be finite, got NaN or inf")
        r, L = self.robot_radius_m, self.arena_size_m
        bad = np.flatnonzero(np.any((arr[:, :2] < r) | (arr[:, :2] > L - r), axis=1))
        if bad.size:
            raise ConfigError(
                f"initial_poses[{bad[0]}] position {arr[bad[0], :2].tolist()} must lie in "
                f"[{r}, {L - r}]^2 (inside the arena, one robot radius from each wall)"
            )
        if self.n_agents > 1:
            d = np.linalg.norm(arr[:, None, :2] - arr[None, :, :2], axis=-1)
            d[np.diag_indices(self.n_agents)] = np.inf
            i, j = np.unravel_index(np.argmin(d), d.shape)
            if d[i, j] < 2 * r:
                raise ConfigError(
                    f"initial_poses: robots {min(i, j)} and {max(i, j)} are {d[i, j]:.3f} m "
                    f"apart; must be >= 2 * robot_radius_m = {2 * r} m"
                )
        arr = arr.copy()
        arr[:, 2] = np.arctan2(np.sin(arr[:, 2]), np.cos(arr[:, 2]))
        arr.setflags(write=False)
        return arr


def _as_float_tuple(name: str, value: Any, n: int) -> tuple[float, ...]:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a sequence of {n} real numbers, got {value!r}") from None
    if arr.size != n:
        raise ConfigError(f"{name} must be a sequence of {n} real numbers, got {value!r}")
    return tuple(float(x) for x in arr)


_FIELDS = frozenset(f.name for f in dataclasses.fields(ScenarioConfig))


def make_config(
    base: ScenarioConfig | None = None, scenario: Scenario | None = None, **kwargs: Any
) -> ScenarioConfig:
    """Build a validated :class:`ScenarioConfig` from keywords.

    Args:
        base: config whose values are used for fields not given (default: the
            scenario's defaults).
        scenario: ``"coverage"`` or ``"crossing"``; the crossing defaults differ
            only in ``n_agents = 4``.
        **kwargs: any field of :class:`ScenarioConfig`.

    Raises:
        ConfigError: an unknown keyword (the message lists the valid ones) or an
            invalid value.
    """
    unknown = sorted(set(kwargs) - _FIELDS)
    if unknown:
        raise ConfigError(
            f"unknown config field(s) {unknown}; valid fields are {sorted(_FIELDS - {'scenario'})}"
        )
    if base is None:
        scen = scenario or "coverage"
        defaults: Mapping[str, Any] = {"n_agents": 4} if scen == "crossing" else {}
        return ScenarioConfig(scenario=scen, **{**defaults, **kwargs})
    values = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
    if scenario is not None:
        values["scenario"] = scenario
    if "n_agents" in kwargs and "initial_poses" not in kwargs:
        values["initial_poses"] = None
    values.update(kwargs)
    return ScenarioConfig(**values)
