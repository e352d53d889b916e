"""A minimal world for testing and benchmarking the tracker without the envs.

:class:`MiniWorld` follows the env contract the tracker relies on (design.md and
:mod:`fov_marl.spaces`): robots integrate their clipped body input exactly over ``dt_s``
(:func:`fov_marl.geometry.integrate_unicycle`) and are clamped to ``[r, L − r]^2``;
robot i detects j iff ``in_fov`` of the true relative position; a detection carries the
relative pose plus N(0, Σ_MEAS) noise truncated at ``meas_noise_clip_sigma`` std; the
observation is encoded as :mod:`fov_marl.spaces` documents (float32). It does not model
collisions or rewards. The estimation package cannot import :mod:`fov_marl.envs`
(imports point one way), so its tests and benchmark use this stand-in.

Scripted motions for the robots (normalised actions), to test the filter against:

* :class:`ModelMotion`: Eq. 20 towards q_m (gain ``k_p``, saturated) plus a white
  velocity perturbation: what the coverage model describes;
* :class:`RandomMotion`: a bounded, smoothly varying random velocity (Ornstein-Uhlenbeck);
* :class:`RingMotion`: coverage-like: each robot heads to its own point on a ring around
  q_m, facing its direction of travel, and stops there (where Eq. 20 is wrong).
* :class:`UniformRandomMotion`: independent uniform actions in ``[-1, 1]^3`` every step
  (the ``random`` baseline policy).

Adversarial motions (scripted from the true poses; they stress the tracker, they are
not a public API: :mod:`fov_marl.adversaries` is):

* :class:`StraightMotion`: straight ahead at full speed, action ``[1, 0, 0]``; robots
  reach a wall, slide along it into a corner and push there;
* :class:`ChargeCentreMotion`: full speed towards the team's centroid, facing the
  direction of travel (with ``spin=True``: at ``ω_max`` all the time, the body
  velocity re-aimed each step so the world direction still points at the centre);
* :class:`ChaseMotion`: full speed towards robot ``(i + 1) mod N`` (cyclic pursuit),
  facing it;
* :class:`WaitChargeMotion`: still (turning slowly) for a per-robot time drawn from
  ``U[wait_min_s, wait_max_s]``, then :class:`ChargeCentreMotion`.

All the adversaries keep commanding full speed where they are (a robot at the centroid
chatters across it at v_max).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from fov_marl.config import ScenarioConfig
from fov_marl.geometry import in_fov, integrate_unicycle, relative_pose, world_to_body
from fov_marl.spaces import CUE_SIZE, SLOT_SIZE, action_to_velocity, velocity_to_action

__all__ = [
    "MiniWorld",
    "ModelMotion",
    "RandomMotion",
    "RingMotion",
    "UniformRandomMotion",
    "StraightMotion",
    "ChargeCentreMotion",
    "ChaseMotion",
    "WaitChargeMotion",
    "random_poses",
    "clustered_poses",
    "calibration_rates",
    "calibration_counter",
    "CalibrationCounter",
]


def random_poses(config: ScenarioConfig, rng: np.random.Generator) -> np.ndarray:
    """``(N, 3)`` random world poses inside the arena, ``init_min_separation_m`` apart."""
    n, r, L = config.n_agents, config.robot_radius_m, config.arena_size_m
    out = np.empty((n, 3))
    k = 0
    sep = min(config.init_min_separation_m, 0.5 * (L - 2 * r) / max(math.sqrt(n), 1.0))
    while k < n:
        p = rng.uniform(r, L - r, 2)
        if k == 0 or np.min(np.linalg.norm(out[:k, :2] - p, axis=1)) >= sep:
            out[k, :2] = p
            out[k, 2] = rng.uniform(-math.pi, math.pi)
            k += 1
    return out


def clustered_poses(
    config: ScenarioConfig, rng: np.random.Generator, size_m: float = 10.0
) -> np.ndarray:
    """``(N, 3)`` random poses in a ``size_m`` square around q_m (clamped to the arena),
    at least ``min(init_min_separation_m, size_m / (2 sqrt N))`` apart, random yaw: a team
    that starts within sight of each other."""
    n, r, L = config.n_agents, config.robot_radius_m, config.arena_size_m
    lo = np.clip(np.asarray(config.density_mean_m, dtype=np.float64) - 0.5 * size_m, r, L - r)
    hi = np.minimum(lo + size_m, L - r)
    sep = min(config.init_min_separation_m, 0.5 * size_m / max(math.sqrt(n), 1.0))
    out = np.empty((n, 3))
    k = 0
    while k < n:
        p = rng.uniform(lo, hi)
        if k == 0 or np.min(np.linalg.norm(out[:k, :2] - p, axis=1)) >= sep:
            out[k, :2] = p
            out[k, 2] = rng.uniform(-math.pi, math.pi)
            k += 1
    return out


class MiniWorld:
    """Kinematics + camera + observation encoding of N robots (see module docstring).

    Args:
        config: the scenario.
        rng: Generator for the measurement noise.
        poses: ``(N, 3)`` initial world poses (default random, from ``rng``).
    """

    def __init__(
        self, config: ScenarioConfig, rng: np.random.Generator, poses: np.ndarray | None = None
    ) -> None:
        self.config = config
        self.rng = rng
        self.poses = random_poses(config, rng) if poses is None else np.array(poses, float)
        self.n = config.n_agents
        self.obs_size = SLOT_SIZE * (self.n - 1) + CUE_SIZE
        self.detected = np.zeros((self.n, self.n), dtype=bool)
        self.t = 0

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Apply ``(N, 3)`` normalised actions for ``dt_s``; returns the new observations."""
        c = self.config
        v, om = action_to_velocity(actions, c.v_max_mps, c.omega_max_radps)
        new = integrate_unicycle(self.poses, v, om, c.dt_s)
        r = c.robot_radius_m
        new[:, :2] = np.clip(new[:, :2], r, c.arena_size_m - r)
        self.poses = new
        self.t += 1
        return self.observe()

    def observe(self) -> np.ndarray:
        """``(N, obs_size)`` float32 observations of the current poses."""
        c = self.config
        n = self.n
        rel = relative_pose(self.poses)  # (N, N, 3): [i, j] = j seen from i
        det = in_fov(rel[..., :2], c.fov_rad, c.detection_range_m)
        det[np.diag_indices(n)] = False
        self.detected = det
        clip = c.meas_noise_clip_sigma
        noise = np.clip(self.rng.standard_normal((n, n, 3)), -clip, clip) * c.meas_std
        meas = rel + noise
        obs = np.zeros((n, self.obs_size), dtype=np.float32)
        for i in range(n):
            js = [j for j in range(n) if j != i]
            slots = np.zeros((n - 1, SLOT_SIZE))
            d = det[i, js]
            m = meas[i, js]
            slots[:, 0] = d
            slots[:, 1] = m[:, 0]
            slots[:, 2] = m[:, 1]
            slots[:, 3] = np.cos(m[:, 2])
            slots[:, 4] = np.sin(m[:, 2])
            slots[~d] = 0.0
            obs[i, : SLOT_SIZE * (n - 1)] = slots.reshape(-1)
            p = self.poses[i]
            if c.scenario == "coverage":
                g = world_to_body(np.asarray(c.density_mean_m), p)
                extra = c.density_sigma_m
            else:
                g = world_to_body(np.asarray(c.density_mean_m), p)
                extra = float(np.hypot(*g))
            obs[i, SLOT_SIZE * (n - 1) :] = [
                p[0],
                p[1],
                math.cos(p[2]),
                math.sin(p[2]),
                g[0],
                g[1],
                extra,
            ]
        return obs

    def true_relative(self, i: int) -> np.ndarray:
        """``(N − 1, 2)`` true positions of i's neighbours in Σ_i (ascending IDs)."""
        js = [j for j in range(self.n) if j != i]
        return world_to_body(self.poses[js, :2], self.poses[i])


def _to_action(config: ScenarioConfig, poses: np.ndarray, v_world: np.ndarray, omega: np.ndarray):
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    vb = np.stack(
        [c * v_world[:, 0] + s * v_world[:, 1], -s * v_world[:, 0] + c * v_world[:, 1]], -1
    )
    sp = np.linalg.norm(vb, axis=1, keepdims=True)
    vb = vb * np.minimum(1.0, config.v_max_mps / np.maximum(sp, 1e-12))
    om = np.clip(omega, -config.omega_max_radps, config.omega_max_radps)
    return velocity_to_action(vb, om, config.v_max_mps, config.omega_max_radps)


def _face(poses: np.ndarray, v_world: np.ndarray, gain: float = 2.0) -> np.ndarray:
    want = np.arctan2(v_world[:, 1], v_world[:, 0])
    err = np.mod(want - poses[:, 2] + math.pi, 2 * math.pi) - math.pi
    moving = np.linalg.norm(v_world, axis=1) > 0.05
    return np.where(moving, gain * err, 0.0)


class ModelMotion:
    """Eq. 20 in the world: ``v = −k_p (p − q_m)`` saturated at v_max, plus white velocity
    noise of std ``noise_mps`` per axis; yaw rate uniform in ``[−ω_max, ω_max]``.

    The world clips every command to v_max, which biases the motion towards slower
    speeds whenever the noisy command exceeds it; to get exactly "Eq. 20 plus white
    noise", use a config whose ``v_max_mps`` is well above ``k_p`` times the largest
    distance to q_m plus a few ``noise_mps``.
    """

    def __init__(
        self,
        config: ScenarioConfig,
        rng: np.random.Generator,
        k_p: float = 0.5,
        noise_mps: float = 1.0,
    ) -> None:
        self.c, self.rng, self.k_p, self.noise = config, rng, k_p, noise_mps

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        c = self.c
        v = -self.k_p * (poses[:, :2] - np.asarray(c.density_mean_m))
        sp = np.linalg.norm(v, axis=1, keepdims=True)
        v = v * np.minimum(1.0, c.v_max_mps / np.maximum(sp, 1e-12))
        v = v + self.noise * self.rng.standard_normal(v.shape)
        om = self.rng.uniform(-1, 1, len(poses)) * c.omega_max_radps
        return _to_action(c, poses, v, om)


class RandomMotion:
    """Smooth random velocity (OU, correlation time ``tau_s``, stationary std per axis
    ``sigma_mps``), capped at v_max; turns to face the direction of travel."""

    def __init__(
        self,
        config: ScenarioConfig,
        rng: np.random.Generator,
        tau_s: float = 2.0,
        sigma_mps: float = 0.6,
    ) -> None:
        self.c, self.rng, self.tau, self.sigma = config, rng, tau_s, sigma_mps
        self.v = None

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        c = self.c
        a = math.exp(-c.dt_s / self.tau)
        if self.v is None:
            self.v = self.sigma * self.rng.standard_normal((len(poses), 2))
        self.v = a * self.v + math.sqrt(1 - a * a) * self.sigma * self.rng.standard_normal(
            self.v.shape
        )
        # bounce off the walls so robots do not sit on the clamp
        r, L = c.robot_radius_m, c.arena_size_m
        near_lo = poses[:, :2] < r + 1.0
        near_hi = poses[:, :2] > L - r - 1.0
        self.v = np.where(near_lo, np.abs(self.v), np.where(near_hi, -np.abs(self.v), self.v))
        return _to_action(c, poses, self.v, _face(poses, self.v))


class RingMotion:
    """Coverage-like motion: robot k heads at v_max (slowing near the end) to its point on
    a ring of radius ``radius_m`` around q_m, facing its direction of travel."""

    def __init__(
        self, config: ScenarioConfig, rng: np.random.Generator, radius_m: float = 6.0
    ) -> None:
        n = config.n_agents
        ang = rng.uniform(0, 2 * math.pi) + 2 * math.pi * np.arange(n) / n
        self.c = config
        self.targets = np.asarray(config.density_mean_m) + radius_m * np.stack(
            [np.cos(ang), np.sin(ang)], -1
        )

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        c = self.c
        v = 0.8 * (self.targets - poses[:, :2])
        sp = np.linalg.norm(v, axis=1, keepdims=True)
        v = v * np.minimum(1.0, c.v_max_mps / np.maximum(sp, 1e-12))
        return _to_action(c, poses, v, _face(poses, v))


class UniformRandomMotion:
    """Independent uniform actions in ``[-1, 1]^3`` for every robot and step (the
    ``random`` baseline): a slow, jittery diffusion (~0.25 m/sqrt(s) per axis)."""

    def __init__(self, config: ScenarioConfig, rng: np.random.Generator) -> None:
        self.rng = rng

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, (len(poses), 3)).astype(np.float32)


def _full_speed_towards(config: ScenarioConfig, poses: np.ndarray, target_world: np.ndarray):
    """``(N, 2)`` world velocity of norm v_max from each robot towards its target."""
    e = target_world - poses[:, :2]
    r = np.linalg.norm(e, axis=1, keepdims=True)
    return config.v_max_mps * e / np.maximum(r, 1e-9)


class StraightMotion:
    """Straight ahead at full speed: action ``[1, 0, 0]`` for every robot, always."""

    def __init__(self, config: ScenarioConfig, rng: np.random.Generator) -> None:
        pass

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        a = np.zeros((len(poses), 3), dtype=np.float32)
        a[:, 0] = 1.0
        return a


class ChargeCentreMotion:
    """Full speed towards the team centroid (mean of all positions).

    ``spin=False``: turns to face the direction of travel. ``spin=True``: yaw rate
    ``+ω_max`` always; the body velocity is the world direction to the centre rotated
    into Σ_i at the start of the step (so it drifts by ``ω_max dt`` during the step).
    """

    def __init__(
        self, config: ScenarioConfig, rng: np.random.Generator, spin: bool = False
    ) -> None:
        self.c, self.spin = config, spin

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        c = self.c
        v = _full_speed_towards(c, poses, poses[:, :2].mean(axis=0, keepdims=True))
        om = np.full(len(poses), c.omega_max_radps) if self.spin else _face(poses, v)
        return _to_action(c, poses, v, om)


class ChaseMotion:
    """Cyclic pursuit: robot i drives at full speed towards robot ``(i + 1) mod N``,
    facing it."""

    def __init__(self, config: ScenarioConfig, rng: np.random.Generator) -> None:
        self.c = config

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        target = np.roll(poses[:, :2], -1, axis=0)
        v = _full_speed_towards(self.c, poses, target)
        return _to_action(self.c, poses, v, _face(poses, v))


class WaitChargeMotion:
    """Still for ``U[wait_min_s, wait_max_s]`` per robot (turning at ``0.2 ω_max``, so the
    camera sweeps), then :class:`ChargeCentreMotion` (facing the direction of travel)."""

    def __init__(
        self,
        config: ScenarioConfig,
        rng: np.random.Generator,
        wait_min_s: float = 5.0,
        wait_max_s: float = 40.0,
    ) -> None:
        self.c = config
        self.wait_steps = np.rint(
            rng.uniform(wait_min_s, wait_max_s, config.n_agents) / config.dt_s
        ).astype(np.int64)
        self.charge = ChargeCentreMotion(config, rng)
        self.t = 0

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        a = self.charge(poses)
        waiting = self.t < self.wait_steps
        a[waiting] = 0.0
        a[waiting, 2] = 0.2
        self.t += 1
        return a


class CalibrationCounter:
    """Accumulates, per category, how often the truth lies inside its confidence ellipse
    and the mean semi-major axis of the ellipses (an ellipse covering the arena is
    "calibrated" and useless, so both are reported).

    Categories of a (robot, neighbour) pair at a step: ``detected`` this step; ``recent``:
    undetected for less than ``long_s``; ``long``: undetected for at least ``long_s``.
    :meth:`stats` adds ``all`` (the three pooled) and ``near``: the pairs, of any
    category, whose true distance is at most ``near_m`` (the neighbours a safety
    constraint is about; not part of ``all``'s sum twice, it is a separate view).
    """

    KEYS = ("detected", "recent", "long")

    def __init__(self, long_s: float = 5.0, near_m: float = 10.0) -> None:
        self.long_s = long_s
        self.near_m = near_m
        keys = (*self.KEYS, "near")
        self.hits = dict.fromkeys(keys, 0)
        self.n = dict.fromkeys(keys, 0)
        self.sum_a = dict.fromkeys(keys, 0.0)

    def add(self, est: Any, truth_body: np.ndarray) -> None:
        """Count one step: ``est`` a :class:`~fov_marl.estimation.BankEstimate` (or
        :class:`~fov_marl.estimation.TrackerEstimate`), ``truth_body`` the true
        neighbour positions in Σ_i shaped like ``est.mean_body``."""
        from fov_marl.geometry import ellipse_distance

        d = ellipse_distance(
            np.asarray(truth_body, dtype=np.float64),
            est.mean_body,
            est.ellipse_a,
            est.ellipse_b,
            est.ellipse_psi,
        )
        inside = d == 0
        long_ = ~est.detected & (est.time_since_seen_s >= self.long_s - 1e-9)
        recent = ~est.detected & ~long_
        near = np.hypot(truth_body[..., 0], truth_body[..., 1]) <= self.near_m
        cats = (("detected", est.detected), ("recent", recent), ("long", long_), ("near", near))
        for key, sel in cats:
            self.hits[key] += int(np.sum(inside[sel]))
            self.n[key] += int(np.sum(sel))
            self.sum_a[key] += float(np.sum(est.ellipse_a[sel]))

    def merge(self, other: CalibrationCounter) -> CalibrationCounter:
        """Add ``other``'s counts into this one (pooling episodes); returns self."""
        for k in self.hits:
            self.hits[k] += other.hits[k]
            self.n[k] += other.n[k]
            self.sum_a[k] += other.sum_a[k]
        return self

    def stats(self) -> dict[str, dict[str, float]]:
        """``{category: {"rate", "n", "mean_a_m"}}`` for the three categories, ``all`` and
        ``near`` (rate NaN where a category is empty)."""
        out = {}
        for k in (*self.KEYS, "near"):
            n = self.n[k]
            out[k] = dict(
                rate=self.hits[k] / n if n else float("nan"),
                n=n,
                mean_a_m=self.sum_a[k] / n if n else float("nan"),
            )
        n = sum(self.n[k] for k in self.KEYS)
        out["all"] = dict(
            rate=sum(self.hits[k] for k in self.KEYS) / n if n else float("nan"),
            n=n,
            mean_a_m=sum(self.sum_a[k] for k in self.KEYS) / n if n else float("nan"),
        )
        return out


def calibration_counter(
    config: ScenarioConfig,
    motion: type | Callable[..., Callable[[np.ndarray], np.ndarray]],
    params: Any = None,
    steps: int = 500,
    seed: int = 0,
    long_s: float = 5.0,
    known_start: bool = True,
    start: Callable[[ScenarioConfig, np.random.Generator], np.ndarray] | None = None,
    near_m: float = 10.0,
) -> CalibrationCounter:
    """One :class:`MiniWorld` episode with every robot driven by ``motion(config, rng)``
    and a :class:`~fov_marl.estimation.TrackerBank` of all robots, counted by a
    :class:`CalibrationCounter` at every step (after the step's update).

    ``start(config, rng)`` gives the initial poses (default :func:`random_poses`; e.g.
    :func:`clustered_poses`), drawn from the world's Generator ``default_rng(seed)``.
    """
    from fov_marl.estimation import TrackerBank

    rng = np.random.default_rng(seed)
    world = MiniWorld(config, rng, poses=None if start is None else start(config, rng))
    pol = motion(config, np.random.default_rng(seed + 7919))
    bank = TrackerBank(config, params, seed=seed)
    bank.reset(world.observe(), initial_poses_world=world.poses if known_start else None)
    counter = CalibrationCounter(long_s, near_m)
    n = config.n_agents
    for _ in range(steps):
        a = pol(world.poses)
        obs = world.step(a)
        bank.step(a, obs)
        counter.add(bank.estimate(), np.stack([world.true_relative(i) for i in range(n)]))
    return counter


def calibration_rates(
    config: ScenarioConfig,
    motion: type | Callable[..., Callable[[np.ndarray], np.ndarray]],
    params: Any = None,
    steps: int = 500,
    seed: int = 0,
    long_s: float = 5.0,
    known_start: bool = True,
) -> dict[str, tuple[float, int]]:
    """How often the true neighbour position lies inside its confidence ellipse.

    Runs a :class:`MiniWorld` episode with every robot driven by ``motion(config, rng)``
    and a :class:`~fov_marl.estimation.TrackerBank` of all robots; each step, for every
    (robot, neighbour) pair, checks whether the true relative position is inside the
    reported ellipse (:func:`fov_marl.geometry.ellipse_distance` == 0). See
    :func:`calibration_counter` for the mean ellipse sizes too.

    Returns:
        ``{"detected": (rate, n), "recent": (rate, n), "long": (rate, n), "all": ...}``:
        neighbours detected this step; undetected for less than ``long_s``; undetected for
        at least ``long_s`` seconds.
    """
    st = calibration_counter(config, motion, params, steps, seed, long_s, known_start).stats()
    return {k: (st[k]["rate"], st[k]["n"]) for k in (*CalibrationCounter.KEYS, "all")}
