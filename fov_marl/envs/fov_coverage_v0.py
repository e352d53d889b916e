"""fov_coverage_v0: coverage of a Gaussian density by robots that see each other only
through a limited-FoV camera and never communicate (paper Section VII-A/B/C).

============================  ==============================================================
Import                        ``from fov_marl.envs import fov_coverage_v0``
API                           PettingZoo ``ParallelEnv`` (``parallel_env``), AEC (``env``),
                              B copies over arrays (``vector_env``, :mod:`fov_marl.envs.vector`)
Agents                        ``robot_0 … robot_{N−1}``, N = ``n_agents`` (default 6)
Action space                  ``Box(-1, 1, (3,), float32)`` per agent
Observation space             ``Box(low, high, (5 (N − 1) + 7,), float32)`` per agent
State space                   ``Box(…, (4 N + 3,), float32)``
Episode                       ``max_cycles`` steps of ``dt_s`` (default 1000 × 0.2 s = 200 s)
============================  ==============================================================

Usage::

    from fov_marl.envs import fov_coverage_v0
    env = fov_coverage_v0.parallel_env(n_agents=6, fov_deg=120.0, render_mode=None)
    obs, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)

Every keyword of ``parallel_env``/``env`` (except ``render_mode``) is a field of
:class:`fov_marl.config.ScenarioConfig` with the paper's value as default; an unknown
keyword, a wrongly typed value (a string, bool or complex number for a real field, a
float for an integer field) or an out-of-range value raises ``ValueError``
(:class:`fov_marl.validation.ConfigError`) naming the field, the value and the allowed
range. Crossing-only fields (``crossing_radius_m``, ...) are type-checked but do not
constrain this scenario. ``scenario="coverage"`` is accepted; another scenario is an
error (use :mod:`fov_marl.envs.fov_crossing_v0`).

Arena and robots
----------------
The arena is the square ``[0, L]²`` (L = ``arena_size_m`` = 40 m), obstacle-free.
Robot i has world pose ``ʷχ_i = [x m, y m, yaw rad]`` and kinematics
``ⁱχ̇_i = ⁱu_i = [vx, vy, ω]`` in its body frame Σ_i, integrated exactly over
``dt_s`` (constant input, rotating heading). After each step positions are
projected onto ``[r, L − r]²`` (r = ``robot_radius_m``), so a robot pushing into a
wall slides along it. Robots pass through each other: collisions are counted, not
resolved physically.

Action space
------------
======  ==============  =======================================================
index   meaning         mapping
======  ==============  =======================================================
0       vx (Σ_i)        ``a₀ · v_max_mps`` (m/s)
1       vy (Σ_i)        ``a₁ · v_max_mps`` (m/s)
2       ω               ``a₂ · omega_max_radps`` (rad/s)
======  ==============  =======================================================

Values outside ``[-1, 1]`` are clipped to it. The planar speed is then limited to
``v_max_mps``: ``(vx, vy)`` is shrunk to norm ``v_max`` when longer (diagonal
commands). An action is any integer or floating array-like of shape ``(3,)`` (list,
tuple, ndarray of any width); strings, bools, complex numbers, object arrays, NaN or
inf, a shape other than ``(3,)``, or an action for an unknown agent raise
``ValueError`` naming the agent; every live agent needs an action.
The mapping is :func:`fov_marl.spaces.action_to_velocity`.

Observation space
-----------------
What robot i's camera reports plus its own mission cue; never ground truth about
neighbours. One slot of 5 entries per other robot ID, in ascending ID order
skipping i, then 7 cue entries:

=========================  ================================  ========================
entries                    meaning                           unit / frame
=========================  ================================  ========================
``5k + 0``                 detected (j ∈ F_i this step)       1.0 or 0.0
``5k + 1``, ``5k + 2``     ⁱx_j, ⁱy_j, noisy                  m, Σ_i
``5k + 3``, ``5k + 4``     cos, sin of θ_j − θ_i, noisy       —
``5(N−1) + 0, 1``          own x, y                           m, Σ_w
``5(N−1) + 2, 3``          cos, sin of own yaw                —
``5(N−1) + 4, 5``          ⁱq_m: density mean                 m, Σ_i
``5(N−1) + 6``             density σ (``density_sigma_m``)    m
=========================  ================================  ========================

Slot k holds robot ``j = k`` if ``k < i`` else ``k + 1``
(:class:`fov_marl.spaces.ObservationLayout` decodes it). A slot is all zeros when j
is not inside F_i, the closed sector of amplitude β = ``fov_deg`` centred on the
body x axis with radius R_d = ``detection_range_m``. Measurement noise is
``N(0, Σ_MEAS)``, Σ_MEAS = ``diag(meas_cov_diag)`` = diag(0.1 m², 0.1 m², 0.5 rad²),
truncated at ``meas_noise_clip_sigma`` = 5 standard deviations so the position
entries stay within ``±(R_d + 5 σ)`` = ±11.58 m, the Box bounds. The density
``φ(q) ∝ exp(−‖q − q_m‖² / 2σ²)`` is known to every robot (the paper computes u*
locally), hence ⁱq_m and σ in the cue.

State (``env.state()``)
-----------------------
For centralised critics: ``[x_k, y_k, cos yaw_k, sin yaw_k]`` for every robot k
(m, Σ_w), then ``q_m`` (m, Σ_w) and σ (m).

Rewards
-------
Cooperative: every robot gets ``reward_eta_gain · (η_t − η_{t−1})`` (default 100 × the
gain of coverage efficiency, so an episode's undiscounted team return is
100 (η_T − η_0)), minus ``collision_penalty`` (10) for each collision it is part
of (centres closer than ``2 robot_radius_m`` = 1 m) and ``safety_penalty`` (1) for
each pair closer than D_s = ``safety_distance_m`` it is part of.

Termination and truncation
--------------------------
Coverage is a continuing task: no termination. All agents are truncated together
after ``max_cycles`` steps (also settable as the attribute ``env.max_cycles``);
``env.agents`` is then empty.

Info
----
``infos[agent]["metrics/<name>"]`` (flat entries, :mod:`fov_marl.infos`; read them with
``fov_marl.infos.metrics_of(info)["<name>"]``; ground truth, for evaluation only,
identical for every agent): ``eta`` (Eq. 21: φ-mass of the union of sensing disks of radius R_s,
φ normalised over the arena), ``t_s``, ``min_distance`` (m, this step),
``min_distance_episode``, ``collisions`` (pairs in contact this step),
``collisions_total`` (collision events so far: a pair entering contact counts once,
however many steps it stays in contact), ``safety_violations`` (pairs closer than D_s
this step), ``safety_violations_total`` (events, like ``collisions_total``).

Rendering
---------
``render_mode="rgb_array"``: ``render()`` returns a ``(640, 640, 3)`` uint8 frame
(density heat map, FoV sectors, sensing disks, robots with heading and ID).
``"human"``: a matplotlib window, updated every step. Policies add layers with
``env.add_render_layer(fn)`` (see :mod:`fov_marl.envs.rendering`).

Ground truth for evaluation: ``env.poses`` ((N, 3) read-only copy), ``env.config``.
"""

from __future__ import annotations

from typing import Any

from fov_marl.envs.base import FovAECEnv, FovEnvBase, aec_env
from fov_marl.envs.subproc import SubprocVectorEnv, make_vector_env
from fov_marl.envs.vector import FovVectorEnv

__all__ = ["raw_env", "parallel_env", "env", "vector_env", "FovCoverageEnv"]


class FovCoverageEnv(FovEnvBase):
    """The coverage ParallelEnv (see the module docstring); a B = 1 view of the batched core."""

    metadata = {**FovEnvBase.metadata, "name": "fov_coverage_v0"}
    scenario = "coverage"


def raw_env(render_mode: str | None = None, **config: Any) -> FovCoverageEnv:
    """The ParallelEnv itself, without wrappers (same as :func:`parallel_env`)."""
    return FovCoverageEnv(render_mode=render_mode, **config)


def parallel_env(render_mode: str | None = None, **config: Any) -> FovCoverageEnv:
    """PettingZoo ParallelEnv; keywords are :class:`~fov_marl.config.ScenarioConfig` fields."""
    return FovCoverageEnv(render_mode=render_mode, **config)


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
    ``eta_method="strip"`` swaps the η of ``metrics["eta"]`` and of the reward for the
    ~3× cheaper :class:`~fov_marl.metrics.StripCoverageMetric` (training; its error is
    documented there); the default ``"exact"`` is the ParallelEnv's η. ``workers = W > 1``
    steps the copies in W processes (:class:`~fov_marl.envs.subproc.SubprocVectorEnv`,
    the same numbers; call ``close()`` when done).
    """
    return make_vector_env(
        "coverage", "fov_coverage_v0", num_envs, config, workers=workers, eta_method=eta_method
    )
