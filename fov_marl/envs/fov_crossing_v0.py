"""fov_crossing_v0: robots whose straight paths to their targets intersect, with a
limited-FoV camera and no communication (paper Section VII-D, Fig. 7).

============================  ==============================================================
Import                        ``from fov_marl.envs import fov_crossing_v0``
API                           PettingZoo ``ParallelEnv`` (``parallel_env``), AEC (``env``),
                              B copies over arrays (``vector_env``, :mod:`fov_marl.envs.vector`)
Agents                        ``robot_0 … robot_{N−1}``, N = ``n_agents`` (default 4)
Action space                  ``Box(-1, 1, (3,), float32)`` per agent
Observation space             ``Box(low, high, (5 (N − 1) + 7,), float32)`` per agent
State space                   ``Box(…, (6 N,), float32)``
Episode                       until every robot is at its target, at most ``max_cycles``
============================  ==============================================================

Usage::

    from fov_marl.envs import fov_crossing_v0
    env = fov_crossing_v0.parallel_env(n_agents=4)
    obs, infos = env.reset(seed=0)

Layout
------
Robot k starts on a circle of radius ``crossing_radius_m`` (12 m) around the arena
centre at angle 2πk/N, facing its target, the antipodal point of the circle; starts
and targets get independent uniform jitter of ± ``crossing_jitter_m`` (0.5 m) per axis
from the seeded generator. All straight paths therefore cross near the centre. A robot
knows only its own target: neighbours' targets are not observable (the paper's
worst-case motion model, Eq. 22, exists for that reason). ``initial_poses=`` overrides
the starts; targets stay antipodal to the default starts.

Arena, kinematics, action space
-------------------------------
As in :mod:`fov_marl.envs.fov_coverage_v0`: square arena ``[0, L]²``, exact body-frame
integration, positions projected onto ``[r, L − r]²``; actions ``[vx, vy, ω]`` in
``[-1, 1]`` scaled by ``v_max_mps``/``omega_max_radps``, clipped to the box, planar speed
limited to ``v_max_mps``; non-numeric (string, bool, complex, object) actions, NaN/inf
and a wrong shape raise ``ValueError`` naming the agent.

Keywords are :class:`fov_marl.config.ScenarioConfig` fields, validated as in the coverage
env. The crossing checks tie ``crossing_radius_m`` (at most ``arena_size_m / 2 -
robot_radius_m``) and ``crossing_jitter_m`` (at most ``arena_size_m / 2``) to the arena,
and the ring to the team: no jitter draw may put two starts (or two targets) closer than
two radii, ``2 R sin(π/N) − 2√2 crossing_jitter_m ≥ 2 robot_radius_m`` (at the defaults:
N ≤ 31; a larger team needs a larger ``crossing_radius_m`` or arena);
coverage-only fields (``density_mean_m``, ``eta_grid_m``, ...) are type-checked but do
not constrain this scenario. ``scenario="crossing"`` is accepted; another scenario is an
error.

Observation space
-----------------
Neighbour slots exactly as in the coverage env (5 per other ID: detected flag, noisy
ⁱx_j, ⁱy_j in m, cos/sin of the noisy relative heading; zeros when j ∉ F_i), then the
own cue:

=========================  ================================  ========================
entries                    meaning                           unit / frame
=========================  ================================  ========================
``5(N−1) + 0, 1``          own x, y                           m, Σ_w
``5(N−1) + 2, 3``          cos, sin of own yaw                —
``5(N−1) + 4, 5``          own target                         m, Σ_i
``5(N−1) + 6``             distance to own target             m
=========================  ================================  ========================

State (``env.state()``)
-----------------------
``[x_k, y_k, cos yaw_k, sin yaw_k]`` for every robot k, then every target ``(x, y)``
(m, Σ_w).

Rewards
-------
Per robot: ``progress_gain`` × metres of progress towards its target this step
(negative when moving away), ``arrival_bonus`` (10) the first step it comes within
``target_tolerance_m`` (0.5 m), minus ``collision_penalty`` (10) per collision and
``safety_penalty`` (1) per D_s violation it is part of.

Termination and truncation
--------------------------
All agents terminate together on the step where every robot is within
``target_tolerance_m`` of its target; otherwise all are truncated after
``max_cycles`` steps. A robot that has arrived stays in the episode (it still moves
and can be hit).

Info
----
``infos[agent]["metrics/<name>"]`` (flat entries, :mod:`fov_marl.infos`; read them with
``fov_marl.infos.metrics_of(info)``; ground truth, evaluation only): ``t_s``, ``min_distance``,
``min_distance_episode``, ``collisions``, ``collisions_total``, ``safety_violations``,
``safety_violations_total``, ``arrived`` (robots within tolerance now),
``arrived_ever`` (robots that have arrived at least once), ``mean_distance_to_target``,
``max_distance_to_target`` (m).

Rendering as in the coverage env, with each robot's target drawn as a cross.
"""

from __future__ import annotations

from typing import Any

from fov_marl.envs.base import FovAECEnv, FovEnvBase, aec_env
from fov_marl.envs.subproc import SubprocVectorEnv, make_vector_env
from fov_marl.envs.vector import FovVectorEnv

__all__ = ["raw_env", "parallel_env", "env", "vector_env", "FovCrossingEnv"]


class FovCrossingEnv(FovEnvBase):
    """The crossing ParallelEnv (see the module docstring); a B = 1 view of the batched core."""

    metadata = {**FovEnvBase.metadata, "name": "fov_crossing_v0"}
    scenario = "crossing"


def raw_env(render_mode: str | None = None, **config: Any) -> FovCrossingEnv:
    """The ParallelEnv itself, without wrappers (same as :func:`parallel_env`)."""
    return FovCrossingEnv(render_mode=render_mode, **config)


def parallel_env(render_mode: str | None = None, **config: Any) -> FovCrossingEnv:
    """PettingZoo ParallelEnv; keywords are :class:`~fov_marl.config.ScenarioConfig` fields."""
    return FovCrossingEnv(render_mode=render_mode, **config)


def env(render_mode: str | None = None, **config: Any) -> FovAECEnv:
    """PettingZoo AEC version, through PettingZoo's ``parallel_to_aec`` conversion
    (order enforced); ``max_cycles`` reads and sets the ParallelEnv's."""
    return aec_env(parallel_env(render_mode=render_mode, **config))


def vector_env(
    num_envs: int = 1, eta_method: str = "exact", workers: int = 1, **config: Any
) -> FovVectorEnv | SubprocVectorEnv:
    """``num_envs`` copies stepped together over arrays (see :mod:`fov_marl.envs.vector`).

    Copy k after ``reset(seed=s)`` is bit-identical to ``parallel_env(**config)`` after
    ``reset(seed=s + k)`` under the same actions; finished copies reset automatically
    in the same step. Keywords are :class:`~fov_marl.config.ScenarioConfig` fields.
    ``eta_method``: ``"exact"`` only (the keyword of ``fov_coverage_v0.vector_env``; the
    crossing reward does not use η). ``workers = W > 1`` steps the copies in W processes
    (:class:`~fov_marl.envs.subproc.SubprocVectorEnv`, the same numbers; call
    ``close()`` when done).
    """
    return make_vector_env(
        "crossing", "fov_crossing_v0", num_envs, config, workers=workers, eta_method=eta_method
    )
