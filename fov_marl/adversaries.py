"""Adversarial policies and adversarial start poses: test helpers for safety filters.

Use them to stress your own safety layer (or policy) the way the project stresses
:class:`fov_marl.wrappers.SafetyFilterWrapper`::

    import numpy as np
    from fov_marl.adversaries import make_adversary, make_start_poses
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.wrappers import SafetyFilterWrapper

    cfg = fov_coverage_v0.parallel_env(n_agents=2).config
    poses = make_start_poses("head_on_pair", cfg, np.random.default_rng(0))
    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses))
    adversary = make_adversary("straight", env)
    obs, infos = env.reset(seed=0)
    adversary.reset(seed=0)
    while env.agents:
        obs, rew, term, trunc, infos = env.step(adversary.act(obs))

:mod:`fov_marl.stress` runs whole sweeps of them (``fov-marl stress``).

Policies
--------
Every adversary follows the policy protocol of :mod:`fov_marl.baselines.registry`
(``reset(seed)``, ``act(obs) -> {agent: (3,) float32 action in [-1, 1]}``; actions are
normalised body-frame ``[vx, vy, ω]``, see :func:`fov_marl.spaces.action_to_velocity`).

Most adversaries **cheat**: they read the ground-truth poses ``env.unwrapped.poses``
of the whole team, which no decentralised policy may do. That makes them stronger
attackers than any honest policy (they always know where the others are, including
the ones their camera does not see), which is the point of a stress test. The column
"reads" below says which:

===================  ======  ==================================================================
name                 reads   behaviour (full speed = ``v_max``)
===================  ======  ==================================================================
``straight``         —       ``[1, 0, 0]``: full speed ahead, never turns
``charge_centre``    truth   full speed at the team's centroid, turning to face it
``spin_charge``      truth   full speed at the centroid while spinning at ±ω_max (sign seeded)
``chase_last_seen``  obs     full speed at the neighbour it last detected, facing it; when it
                             loses it, on to the last-seen point and beyond, blind
``wait_charge``      truth   stands still ``wait_steps`` steps, then charges the nearest
                             teammate, facing it
``head_on``          truth   full speed straight at the nearest teammate without turning: the
                             body-frame motion points at it, so it moves sideways or
                             backwards, blind, whenever the teammate is not ahead
``rush``             obs     full speed to the density peak q_m (coverage) or its own target
                             (crossing), facing it, ignoring everyone
``random``           —       uniform actions in ``[-1, 1]³`` from the seeded generator
``wall_slide``       truth   pushes 45° into its nearest wall while moving along it towards
                             the nearest teammate, turned away from the wall: the env
                             projects it onto the wall, so it slides sideways, blind
===================  ======  ==================================================================

"truth" = ``env.unwrapped.poses``; "obs" = only the robot's own observation (its own
pose and goal from the cue, its detections).

A robot with no teammate (N = 1) drives straight ahead. Randomness (``random``'s
actions, ``spin_charge``'s spin signs) comes only from the ``np.random.Generator``
seeded by :meth:`Adversary.reset`; the other adversaries are deterministic functions of
the state, so the same seed gives the same actions.

Starts
------
:func:`make_start_poses` returns ``initial_poses`` ``(N, 3)`` (world ``[x m, y m, yaw
rad]``, for the envs' ``initial_poses=`` keyword) for ``"random"`` (``None``: the env's
own seeded draw), ``"clustered"``, ``"corner"``, ``"wall"`` and ``"head_on_pair"``. The
packed starts keep every pair at least ``collision_distance_m + margin_m`` (1.1 m by
default) apart, i.e. out of contact but deep inside D_s (2 m).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.geometry import body_to_world, world_to_body
from fov_marl.validation import check_seed, has_attribute

__all__ = [
    "Adversary",
    "make_adversary",
    "available_adversaries",
    "register_adversary",
    "make_start_poses",
    "available_starts",
]


# ============================================================== the policies
class Adversary:
    """Base class: a team policy that drives every robot into trouble.

    Subclasses implement :meth:`_team_actions`, returning ``(N, 3)`` actions for all
    robots of the env (rows of finished robots are ignored); :meth:`act` clips them to
    ``[-1, 1]``, casts to float32 and keeps the agents present in ``obs``.

    Args:
        env: a fov_marl ParallelEnv (``fov_coverage_v0`` / ``fov_crossing_v0``), possibly
            wrapped (e.g. in :class:`~fov_marl.wrappers.SafetyFilterWrapper`); the
            adversaries that cheat read ``env.unwrapped.poses``.
    """

    name: ClassVar[str] = "adversary"

    def __init__(self, env: Any) -> None:
        base = env.unwrapped
        if not hasattr(base, "config") or not has_attribute(base, "poses"):
            raise ValueError(
                "adversaries need a fov_marl environment (with .config and .poses), "
                f"got {type(base).__name__}"
            )
        self._base = base
        self.config: ScenarioConfig = base.config
        self.possible_agents: list[str] = list(base.possible_agents)
        self._index: dict[str, int] = dict(base.agent_name_mapping)
        self._rng = np.random.default_rng()
        self.num_steps = 0

    # ------------------------------------------------------------ protocol
    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; same seed, same actions."""
        self._rng = np.random.default_rng(check_seed("seed", seed))
        self.num_steps = 0
        self._reset_state()

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Actions ``(3,)`` float32 in ``[-1, 1]`` for every agent in ``obs``."""
        team = np.clip(self._team_actions(obs), -1.0, 1.0).astype(np.float32)
        self.num_steps += 1
        return {a: team[self._index[a]].copy() for a in self.possible_agents if a in obs}

    # ------------------------------------------------------------- hooks
    def _reset_state(self) -> None:
        """Per-episode state (after the generator is seeded)."""

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        raise NotImplementedError

    # ----------------------------------------------------------- helpers
    @property
    def n_agents(self) -> int:
        return self.config.n_agents

    def _poses_world(self) -> np.ndarray:
        """``(N, 3)`` ground-truth world poses (cheating; see the module docstring)."""
        return np.asarray(self._base.poses, dtype=np.float64)

    def _nearest_teammate_world(self, poses_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position ``(N, 2)`` m of each robot's nearest teammate and a validity mask ``(N,)``."""
        n = poses_world.shape[0]
        if n < 2:
            return np.zeros((n, 2)), np.zeros(n, dtype=bool)
        p = poses_world[:, :2]
        d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        np.fill_diagonal(d, np.inf)
        j = np.argmin(d, axis=1)
        return p[j], np.ones(n, dtype=bool)

    def _drive_at(
        self,
        target_world: np.ndarray,
        poses_world: np.ndarray,
        *,
        face: bool,
        omega_action: np.ndarray | None = None,
        valid: np.ndarray | None = None,
        stop_at_target: bool = False,
    ) -> np.ndarray:
        """Full-speed actions towards world points.

        Args:
            target_world: ``(N, 2)`` world points (m).
            poses_world: ``(N, 3)`` robot poses.
            face: turn towards the target at up to ω_max (else keep the heading, unless
                ``omega_action`` is given).
            omega_action: ``(N,)`` normalised yaw-rate actions overriding ``face``.
            valid: ``(N,)`` rows whose target exists; the others drive straight ahead.
            stop_at_target: slow down so as not to overshoot the target within a step.

        Returns:
            ``(N, 3)`` actions. The body-frame velocity is pre-rotated by ``−ω dt / 2``
            so that the chord of the exactly integrated step (the env holds the body
            velocity constant while the robot turns) points at the target.
        """
        cfg = self.config
        n = poses_world.shape[0]
        p_body = world_to_body(target_world, poses_world)
        dist_m = np.linalg.norm(p_body, axis=-1)
        bearing_rad = np.arctan2(p_body[:, 1], p_body[:, 0])
        if omega_action is not None:
            w_act = np.asarray(omega_action, dtype=np.float64)
        elif face:
            w_act = np.clip(bearing_rad / (cfg.omega_max_radps * cfg.dt_s), -1.0, 1.0)
        else:
            w_act = np.zeros(n)
        heading = bearing_rad - 0.5 * w_act * cfg.omega_max_radps * cfg.dt_s
        speed = np.ones(n)
        if stop_at_target:
            speed = np.minimum(1.0, dist_m / (cfg.v_max_mps * cfg.dt_s))
        out = np.column_stack([speed * np.cos(heading), speed * np.sin(heading), w_act])
        ok = dist_m > 1e-9 if valid is None else (np.asarray(valid, dtype=bool) & (dist_m > 1e-9))
        out[~ok] = (1.0, 0.0, 0.0)
        return out


_REGISTRY: dict[str, Callable[..., Adversary]] = {}


def register_adversary(cls: type[Adversary]) -> type[Adversary]:
    """Class decorator: register an :class:`Adversary` subclass under ``cls.name``."""
    _REGISTRY[cls.name] = cls
    return cls


def available_adversaries() -> list[str]:
    """Names accepted by :func:`make_adversary`, sorted."""
    return sorted(_REGISTRY)


def make_adversary(name: str, env: Any, **kwargs: Any) -> Adversary:
    """Build the adversary ``name`` for ``env`` (a fov_marl ParallelEnv or wrapper).

    Args:
        name: one of :func:`available_adversaries`.
        env: the env the adversary will act in.
        **kwargs: the adversary's options (e.g. ``wait_steps`` of ``wait_charge``).

    Raises:
        ValueError: unknown name (the message lists the valid ones) or unknown option.
    """
    if name not in _REGISTRY:
        raise ValueError(
            f"unknown adversary {name!r}; available adversaries are {available_adversaries()}"
        )
    try:
        return _REGISTRY[name](env, **kwargs)
    except TypeError as exc:
        raise ValueError(f"adversary {name!r}: bad options {sorted(kwargs)} ({exc})") from None


@register_adversary
class Straight(Adversary):
    """Full speed ahead, ``[1, 0, 0]``, never turning."""

    name = "straight"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.tile([1.0, 0.0, 0.0], (self.n_agents, 1))


@register_adversary
class ChargeCentre(Adversary):
    """Full speed at the team's ground-truth centroid, turning to face it (cheats)."""

    name = "charge_centre"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        poses = self._poses_world()
        centre = np.broadcast_to(poses[:, :2].mean(axis=0), (self.n_agents, 2))
        return self._drive_at(
            centre, poses, face=True, valid=np.full(self.n_agents, self.n_agents > 1)
        )


@register_adversary
class SpinCharge(Adversary):
    """Full speed at the team's centroid while spinning at full yaw rate (cheats).

    Args:
        spin: ``+1`` or ``-1`` for every robot, or ``None`` (default) for a sign per
            robot drawn from the seeded generator at :meth:`reset`.
    """

    name = "spin_charge"

    def __init__(self, env: Any, spin: int | None = None) -> None:
        super().__init__(env)
        if spin not in (None, 1, -1):
            raise ValueError(f"spin must be None, 1 or -1, got {spin!r}")
        self.spin = spin
        self._spin_sign = np.ones(self.n_agents)

    def _reset_state(self) -> None:
        if self.spin is None:
            self._spin_sign = self._rng.choice([-1.0, 1.0], size=self.n_agents)
        else:
            self._spin_sign = np.full(self.n_agents, float(self.spin))

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        poses = self._poses_world()
        centre = np.broadcast_to(poses[:, :2].mean(axis=0), (self.n_agents, 2))
        out = self._drive_at(
            centre,
            poses,
            face=False,
            omega_action=self._spin_sign,
            valid=np.full(self.n_agents, self.n_agents > 1),
        )
        out[:, 2] = self._spin_sign
        return out


@register_adversary
class ChaseLastSeen(Adversary):
    """Chase the neighbour last detected in the robot's own observation (honest inputs).

    While a neighbour is detected the robot drives at it at full speed, facing it
    (it keeps the neighbour it chases while that one stays detected, else takes the
    nearest detected one). When it loses it, it drives on to the last-seen world point
    (``arrive_m`` from it) and then keeps going in the same direction at full speed
    without turning: blind pursuit. A robot that has never detected anyone drives
    straight ahead. Only the robot's observation is used (own pose from the cue).

    Args:
        arrive_m: distance (m) at which the last-seen point counts as reached.
    """

    name = "chase_last_seen"

    def __init__(self, env: Any, arrive_m: float = 0.3) -> None:
        super().__init__(env)
        if not (isinstance(arrive_m, int | float) and arrive_m > 0):
            raise ValueError(f"arrive_m must be a positive number, got {arrive_m!r}")
        self.arrive_m = float(arrive_m)
        self._layouts = self._base.layouts

    def _reset_state(self) -> None:
        n = self.n_agents
        self._target_id = np.full(n, -1, dtype=np.int64)
        self._last_seen_world = np.full((n, 2), np.nan)
        self._dir_world = np.full((n, 2), np.nan)  # unit vector of the last chase leg

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        out = np.tile([1.0, 0.0, 0.0], (self.n_agents, 1))
        for a, o in obs.items():
            i = self._index[a]
            lay = self._layouts[i]
            own = lay.own_pose_world(o)
            det = lay.decode(o)
            if det.ids.size:
                k = np.flatnonzero(det.ids == self._target_id[i])
                if k.size == 0:
                    k = np.array([int(np.argmin(np.linalg.norm(det.p_body, axis=1)))])
                self._target_id[i] = det.ids[k[0]]
                self._last_seen_world[i] = body_to_world(det.p_body[k[0]], own)
            if np.isnan(self._last_seen_world[i, 0]):
                continue  # never saw anyone: straight ahead
            d_world = self._last_seen_world[i] - own[:2]
            dist = float(np.hypot(*d_world))
            if det.ids.size or dist > self.arrive_m:
                if dist > 1e-9:
                    self._dir_world[i] = d_world / dist
                out[i] = self._drive_at(self._last_seen_world[i][None], own[None], face=True)[0]
            elif not np.isnan(self._dir_world[i, 0]):
                # reached the last-seen point without finding it: keep going, blind
                ahead = own[:2] + self._dir_world[i]
                out[i] = self._drive_at(ahead[None], own[None], face=False)[0]
        return out


@register_adversary
class WaitCharge(Adversary):
    """Stand still ``wait_steps`` steps, then charge the nearest teammate facing it (cheats).

    Args:
        wait_steps: steps of standing still (default 20 = 4 s at dt = 0.2 s), >= 0.
    """

    name = "wait_charge"

    def __init__(self, env: Any, wait_steps: int = 20) -> None:
        super().__init__(env)
        if isinstance(wait_steps, bool) or not isinstance(wait_steps, int | np.integer):
            raise ValueError(f"wait_steps must be an integer >= 0, got {wait_steps!r}")
        if wait_steps < 0:
            raise ValueError(f"wait_steps must be an integer >= 0, got {wait_steps!r}")
        self.wait_steps = int(wait_steps)

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.num_steps < self.wait_steps:
            return np.zeros((self.n_agents, 3))
        poses = self._poses_world()
        target, valid = self._nearest_teammate_world(poses)
        return self._drive_at(target, poses, face=True, valid=valid)


@register_adversary
class HeadOn(Adversary):
    """Full speed straight at the nearest teammate, never turning (cheats).

    The body-frame velocity points at the teammate, so whenever it is not ahead the
    robot moves sideways or backwards, outside its own camera sector.
    """

    name = "head_on"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        poses = self._poses_world()
        target, valid = self._nearest_teammate_world(poses)
        return self._drive_at(target, poses, face=False, valid=valid)


@register_adversary
class Rush(Adversary):
    """Full speed to the density peak (coverage) or own target (crossing), facing it.

    Ignores everyone; reads only its own cue (``ObservationLayout.goal_body``). It
    slows down within one step of the goal so it stops on it instead of oscillating;
    in coverage the whole team converges on the same point q_m.
    """

    name = "rush"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        out = np.tile([1.0, 0.0, 0.0], (self.n_agents, 1))
        for a, o in obs.items():
            i = self._index[a]
            lay = self._base.layouts[i]
            own = lay.own_pose_world(o)
            goal_world = body_to_world(lay.goal_body(o), own)
            out[i] = self._drive_at(goal_world[None], own[None], face=True, stop_at_target=True)[0]
            if np.hypot(*lay.goal_body(o)) <= 1e-9:
                out[i] = 0.0
        return out


@register_adversary
class RandomActions(Adversary):
    """Uniform actions in ``[-1, 1]³``; ``N × 3`` draws per step whatever is live."""

    name = "random"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, size=(self.n_agents, 3))


@register_adversary
class WallSlide(Adversary):
    """Push into the nearest wall while sliding along it towards the nearest teammate (cheats).

    The commanded world direction is ``(n + t) / √2`` (n: outward normal of the
    robot's nearest wall, t: the wall's tangent pointing towards the nearest teammate's
    projection on it), and the robot turns to face away from the wall. The env projects
    positions onto the arena, so the robot ends up sliding along the wall at
    ``v_max / √2``, sideways to its camera.
    """

    name = "wall_slide"

    def _team_actions(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        cfg = self.config
        poses = self._poses_world()
        p = poses[:, :2]
        L = cfg.arena_size_m
        gaps = np.column_stack([p[:, 0], L - p[:, 0], p[:, 1], L - p[:, 1]])  # -x, +x, -y, +y
        normals = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
        n_world = normals[np.argmin(gaps, axis=1)]
        t_world = np.column_stack([-n_world[:, 1], n_world[:, 0]])
        mate, valid = self._nearest_teammate_world(poses)
        side = np.sign(np.sum((mate - p) * t_world, axis=1))
        side[(side == 0) | ~valid] = 1.0
        dir_world = (n_world + side[:, None] * t_world) / math.sqrt(2.0)
        away_rad = np.arctan2(-n_world[:, 1], -n_world[:, 0])
        err = np.arctan2(np.sin(away_rad - poses[:, 2]), np.cos(away_rad - poses[:, 2]))
        w_act = np.clip(err / (cfg.omega_max_radps * cfg.dt_s), -1.0, 1.0)
        return self._drive_at(p + dir_world, poses, face=False, omega_action=w_act)


# ================================================================ the starts
_STARTS = ("random", "clustered", "corner", "wall", "head_on_pair")


def available_starts() -> list[str]:
    """Names accepted by :func:`make_start_poses`."""
    return list(_STARTS)


def make_start_poses(
    start: str,
    config: ScenarioConfig,
    rng: np.random.Generator,
    *,
    margin_m: float = 0.1,
    **kwargs: Any,
) -> np.ndarray | None:
    """Adversarial start poses for the envs' ``initial_poses=`` keyword.

    Args:
        start: one of :func:`available_starts`:

            * ``"random"``: ``None`` (the env draws its own seeded random start).
            * ``"clustered"``: uniform in a ``side_m`` × ``side_m`` square (default
              6 m) centred on ``centre_m`` (default the arena centre), random yaw.
              Dart throwing; a jittered grid when throwing fails.
            * ``"corner"``: packed on a square lattice of pitch ``sep`` into a corner
              chosen by ``rng``, ``facing="corner"`` (default: every robot faces the
              corner point, i.e. the walls) or ``"each_other"`` (the group's centroid).
            * ``"wall"``: rows along a wall chosen by ``rng``, pitch ``sep``, centred on
              it; ``facing="wall"`` (default: facing the wall) or ``"each_other"``
              (neighbours along the row face each other in pairs).
            * ``"head_on_pair"``: robots 0 and 1 ``gap_m`` apart (default 2.6 m) around
              the arena centre on an axis of random direction, facing each other; the
              others uniform at least ``keep_out_m`` (default 8 m) from the centre and
              ``init_min_separation_m`` from everyone, random yaw.

        config: the scenario config (``env.config``): N, arena, robot radius.
        rng: the generator all randomness comes from.
        margin_m: packed starts keep pairs ``sep = collision_distance_m + margin_m``
            apart (m), > 0.
        **kwargs: the start's options named above.

    Returns:
        ``(N, 3)`` world poses ``[x m, y m, yaw rad]`` inside ``[r, L − r]²``, or None.

    Raises:
        ValueError: unknown start or option, or the robots do not fit.
    """
    if start not in _STARTS:
        raise ValueError(f"unknown start {start!r}; available starts are {available_starts()}")
    if not (isinstance(margin_m, int | float) and margin_m > 0):
        raise ValueError(f"margin_m must be a positive number, got {margin_m!r}")
    sep_m = config.collision_distance_m + float(margin_m)
    allowed = {
        "random": set(),
        "clustered": {"side_m", "centre_m"},
        "corner": {"facing"},
        "wall": {"facing"},
        "head_on_pair": {"gap_m", "keep_out_m"},
    }[start]
    bad = sorted(set(kwargs) - allowed)
    if bad:
        raise ValueError(f"start {start!r} takes options {sorted(allowed)}, got {bad}")
    if start == "random":
        return None
    fn = {
        "clustered": _clustered,
        "corner": _corner,
        "wall": _wall,
        "head_on_pair": _head_on_pair,
    }[start]
    poses = fn(config, rng, sep_m, **kwargs)
    poses[:, 2] = np.arctan2(np.sin(poses[:, 2]), np.cos(poses[:, 2]))
    _check_poses(
        config, poses, start, sep_m if start != "head_on_pair" else 2 * config.robot_radius_m
    )
    return poses


def _check_poses(config: ScenarioConfig, poses: np.ndarray, start: str, sep_m: float) -> None:
    r, L = config.robot_radius_m, config.arena_size_m
    if np.any(poses[:, :2] < r) or np.any(poses[:, :2] > L - r):
        raise ValueError(f"start {start!r}: the robots do not fit in a {L} m arena")
    if poses.shape[0] > 1:
        d = np.linalg.norm(poses[:, None, :2] - poses[None, :, :2], axis=-1)
        np.fill_diagonal(d, np.inf)
        if d.min() < sep_m - 1e-9:
            raise ValueError(
                f"start {start!r}: cannot place {poses.shape[0]} robots {sep_m} m apart"
            )


def _dart_throw(
    rng: np.random.Generator,
    n: int,
    lo: np.ndarray,
    hi: np.ndarray,
    sep_m: float,
    placed: np.ndarray | None = None,
    keep_out: tuple[np.ndarray, float] | None = None,
    tries: int = 100,
) -> np.ndarray | None:
    """``(n, 2)`` points uniform in the box ``[lo, hi]`` at least ``sep_m`` apart (and from
    ``placed``, and outside the disk ``keep_out = (centre, radius)``), or None."""
    fixed = np.zeros((0, 2)) if placed is None else np.asarray(placed, dtype=np.float64)
    pos = np.empty((n, 2))
    for i in range(n):
        others = np.concatenate([fixed, pos[:i]])
        for _ in range(tries):
            cand = rng.uniform(lo, hi, size=(100, 2))
            ok = np.ones(100, dtype=bool)
            if others.shape[0]:
                d2 = np.sum((cand[:, None, :] - others[None, :, :]) ** 2, axis=-1)
                ok &= np.all(d2 >= sep_m**2, axis=1)
            if keep_out is not None:
                ok &= np.sum((cand - keep_out[0]) ** 2, axis=1) >= keep_out[1] ** 2
            if ok.any():
                pos[i] = cand[np.argmax(ok)]
                break
        else:
            return None
    return pos


def _clustered(
    config: ScenarioConfig,
    rng: np.random.Generator,
    sep_m: float,
    side_m: float = 6.0,
    centre_m: tuple[float, float] | None = None,
) -> np.ndarray:
    n, L, r = config.n_agents, config.arena_size_m, config.robot_radius_m
    side = min(float(side_m), L - 2 * r)
    c = np.full(2, L / 2) if centre_m is None else np.asarray(centre_m, dtype=np.float64)
    c = np.clip(c, r + side / 2, L - r - side / 2)
    lo, hi = c - side / 2, c + side / 2
    pos = _dart_throw(rng, n, lo, hi, sep_m, tries=20)
    if pos is None:  # jittered grid: k × k cells of side ≥ sep, a random subset of them
        k = math.ceil(math.sqrt(n))
        cell = side / k
        if cell < sep_m:
            raise ValueError(
                f"start 'clustered': {n} robots do not fit {sep_m} m apart in a {side} m "
                "square; raise side_m"
            )
        cells = rng.permutation(k * k)[:n]
        centres = lo + cell * (np.column_stack([cells % k, cells // k]) + 0.5)
        pos = centres + rng.uniform(-1, 1, size=(n, 2)) * (cell - sep_m) / 2
    yaw = rng.uniform(-np.pi, np.pi, size=n)
    return np.column_stack([pos, yaw])


def _lattice_offsets(n: int, sep_m: float, ncols: int | None = None) -> np.ndarray:
    """``(n, 2)`` lattice points ``(a, b)·sep`` (a, b ≥ 0) nearest the origin, nearest first."""
    m = math.ceil(math.sqrt(n)) + 1 if ncols is None else ncols
    a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    ab = np.column_stack([a.ravel(), b.ravel()]).astype(np.float64)
    order = np.lexsort((ab[:, 1], ab[:, 0], np.hypot(ab[:, 0], ab[:, 1])))
    return ab[order[:n]] * sep_m


def _corner(
    config: ScenarioConfig, rng: np.random.Generator, sep_m: float, facing: str = "corner"
) -> np.ndarray:
    if facing not in ("corner", "each_other"):
        raise ValueError(f"start 'corner': facing must be 'corner' or 'each_other', got {facing!r}")
    n, L, r = config.n_agents, config.arena_size_m, config.robot_radius_m
    d0 = r + 0.05
    k = int(rng.integers(4))  # corner: 0 (0,0), 1 (L,0), 2 (L,L), 3 (0,L)
    sx, sy = (1.0, -1.0, -1.0, 1.0)[k], (1.0, 1.0, -1.0, -1.0)[k]
    corner = np.array([0.0 if sx > 0 else L, 0.0 if sy > 0 else L])
    off = d0 + _lattice_offsets(n, sep_m)
    pos = corner + off * np.array([sx, sy])
    aim = corner if facing == "corner" else pos.mean(axis=0)
    d = aim - pos
    yaw = np.arctan2(d[:, 1], d[:, 0])
    at = np.hypot(d[:, 0], d[:, 1]) < 1e-9  # a robot on the centroid faces the corner
    yaw[at] = np.arctan2(corner[1] - pos[at, 1], corner[0] - pos[at, 0])
    return np.column_stack([pos, yaw])


def _wall(
    config: ScenarioConfig, rng: np.random.Generator, sep_m: float, facing: str = "wall"
) -> np.ndarray:
    if facing not in ("wall", "each_other"):
        raise ValueError(f"start 'wall': facing must be 'wall' or 'each_other', got {facing!r}")
    n, L, r = config.n_agents, config.arena_size_m, config.robot_radius_m
    d0 = r + 0.05
    per_row = int(math.floor((L - 2 * d0) / sep_m)) + 1
    rows = np.arange(n) // per_row
    cols = np.arange(n) % per_row
    in_row = np.minimum(per_row, n - rows * per_row)
    along = L / 2 + (cols - (in_row - 1) / 2) * sep_m  # centred on the wall
    depth = d0 + rows * sep_m
    k = int(rng.integers(4))  # wall: 0 y=0, 1 x=L, 2 y=L, 3 x=0
    normal = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])[k]  # outward
    tangent = np.array([-normal[1], normal[0]])
    wall_mid = np.full(2, L / 2) + normal * (L / 2)
    pos = wall_mid[None] - depth[:, None] * normal + (along - L / 2)[:, None] * tangent
    if facing == "wall":
        yaw = np.full(n, math.atan2(normal[1], normal[0]))
    else:
        t = np.where(cols % 2 == 0, 1.0, -1.0)[:, None] * tangent
        yaw = np.arctan2(t[:, 1], t[:, 0])
    return np.column_stack([pos, yaw])


def _head_on_pair(
    config: ScenarioConfig,
    rng: np.random.Generator,
    sep_m: float,
    gap_m: float = 2.6,
    keep_out_m: float = 8.0,
) -> np.ndarray:
    n, L, r = config.n_agents, config.arena_size_m, config.robot_radius_m
    if n < 2:
        raise ValueError("start 'head_on_pair' needs n_agents >= 2")
    if not gap_m >= 2 * r:
        raise ValueError(f"start 'head_on_pair': gap_m must be >= 2 * robot_radius_m, got {gap_m}")
    c = np.full(2, L / 2)
    axis_rad = float(rng.uniform(-np.pi, np.pi))
    e = np.array([math.cos(axis_rad), math.sin(axis_rad)])
    pair = np.array([[*(c - e * gap_m / 2), axis_rad], [*(c + e * gap_m / 2), axis_rad + math.pi]])
    if n == 2:
        return pair
    lo, hi = np.full(2, r + 0.5), np.full(2, L - r - 0.5)
    keep = max(float(keep_out_m), gap_m / 2 + config.init_min_separation_m)
    rest = _dart_throw(
        rng, n - 2, lo, hi, config.init_min_separation_m, placed=pair[:, :2], keep_out=(c, keep)
    )
    if rest is None:
        raise ValueError(
            f"start 'head_on_pair': cannot place {n - 2} more robots "
            f"{config.init_min_separation_m} m apart outside {keep} m of the pair"
        )
    yaw = rng.uniform(-np.pi, np.pi, size=n - 2)
    return np.concatenate([pair, np.column_stack([rest, yaw])])
