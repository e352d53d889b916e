"""Permutation-invariant, size-independent actor-critic for PPO, with an optional CTDE critic.

``train(..., arch="set")`` (``fov-marl train --arch set``) trains
:class:`SetActorCriticPolicy`; ``ctde=True`` (``--ctde``) gives the critic the global
state expressed agent-centrically (MAPPO-style: centralised training, decentralised
execution). The actor is the network of :mod:`fov_marl.baselines.learned` (features,
pooling and sizes are defined there); :func:`actor_weights` exports it for that numpy
forward pass, which is tested equal to this module's actor within 1e-5.

Actor (reads the robot's own observation only)
----------------------------------------------
Neighbour slots ``(N − 1, 5)`` -> per-entry MLP φ -> masked mean and max (masked by the
detected flag) ; cue ``(7,)`` -> ψ ; ``[mean, max, ψ, count / 5]`` -> head -> Gaussian
mean (SB3's ``action_net``) and a state-independent log-std. N is read from the
observation length at every forward pass, so the same weights take any N.

Critic
------
Without CTDE: the same structure with its own weights, on the own observation. With
CTDE the training observation of every slot is the own observation followed by the
*critic entries* of :class:`CtdeVecEnvWrapper` (one per other robot, in slot order):

=====  =========================================  ==================
entry  meaning                                    unit / frame
=====  =========================================  ==================
0      present (1; 0 = padding)                   —
1, 2   ⁱx_k, ⁱy_k: robot k relative to robot i    m, Σ_i, exact
3, 4   cos, sin of θ_k − θ_i                      exact
=====  =========================================  ==================

They are a set again (φ_c, masked mean/max with scale ``arena_half_m``); with the
density mean (already in the cue, Σ_i) they are ``env.state()`` seen from robot i. They
are computed from the observations themselves (each robot's cue holds its exact world
pose), so they also exist for the ``terminal_observation`` SB3 bootstraps from. The
actor never reads them (:func:`split_obs`; a test perturbs them and checks the action).

Why SB3 and not BenchMARL/TorchRL
---------------------------------
Parameter sharing over the batched env is already one SB3 ``VecEnv`` slot per robot
(:mod:`fov_marl.training.vec_env`), with checkpoints, TensorBoard and config/CLI
plumbing in place; on 2 CPU cores the env (and, behind the filter, the particle
filters and QPs) dominates a sample, not the learner, so a second framework would add
maintenance (BenchMARL pins TorchRL 0.11; its PettingZoo wrapper needs flat infos,
design.md) without training faster. MAPPO's one ingredient beyond shared PPO, the
centralised critic, is a critic input here: the set-structured extractor below.

What was measured (N = 6, β = 120°, 2-core machine; README "Learned policy")
--------------------------------------------------------------------------
Without the filter the set policy trains at ~2,200-3,300 samples/s (hidden 64,
``n_epochs`` 5, ``batch_size`` 2048; the env alone steps ~30,000 samples/s, so the
learner dominates) and after 2.6 M timesteps covers as well as pfcbf (final η within
noise). Behind :class:`~fov_marl.wrappers.VectorSafetyFilterWrapper` training runs at
~400-600 samples/s. An unbounded Gaussian mean saturates far outside ``[-1, 1]``
(full-speed circling or jitter to hold a position), where the action-based shaping terms
lose their gradient: hence ``bounded_mean``.

Policies trained without the filter never stop. Their median commanded speed is v_max
in every 100-step window of the episode, while pfcbf's u* drops to 0 once the team has
settled. The filter changes ~90% of their actions and freezes robots that drive
without looking at their neighbours, which costs η. A from-scratch run with
``bounded_mean`` and ``action_cost_coef = 0.3`` covers better than pfcbf without the
filter (final η 0.9991, above pfcbf's on 20 of 20 seeds). It still circles at
0.99 m/s, and reaches only 0.93 behind the filter. Fine-tuning such a policy behind
the filter did not change that.

The shipped model was instead trained *from scratch behind the filter*, with P_T = 500
particles: ~1,700 samples/s, 1.5 M timesteps in 911 s. It learnt to slow down (median
commanded speed 0.25-0.32 m/s after the first 20 s) and covers behind the filter about
as well as pfcbf. Without the filter it collides: it relies on the filter it was trained
behind (README, "Learned policy").

SB3 hooks used
--------------
The features extractor is SB3's ``FlattenExtractor`` (the raw observation); the
custom ``mlp_extractor`` (:class:`SetActorCritic`) parses it differently for the actor
and the critic, which SB3's pair of per-side extractors cannot (they must share one
class and one output size). SB3's orthogonal initialisation applies to every layer.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from torch import nn

from fov_marl.baselines.learned import CUE_FEATURES, MODEL_FORMAT, NEIGHBOUR_FEATURES
from fov_marl.infos import METRICS_PREFIX
from fov_marl.spaces import (
    CUE_GOAL_BODY,
    CUE_P_WORLD,
    CUE_SCALAR,
    CUE_SIZE,
    CUE_YAW_CS,
    SLOT_DETECTED,
    SLOT_P_BODY,
    SLOT_SIZE,
    SLOT_YAW_CS,
)

__all__ = [
    "SetActorCritic",
    "SetActorCriticPolicy",
    "CtdeVecEnvWrapper",
    "agent_centric_state",
    "actor_weights",
    "split_obs",
    "default_feature_scales",
    "STATE_ENTRY",
]

#: entries per critic state entry (present, x, y, cos, sin)
STATE_ENTRY = 5
_ACT = {"tanh": nn.Tanh, "relu": nn.ReLU}


def default_feature_scales(config: Any) -> dict[str, Any]:
    """The fixed feature scales of a scenario config (``detection_range_m``, arena)."""
    L = float(config.arena_size_m)
    return {
        "neighbour_m": float(config.detection_range_m),
        "arena_half_m": L / 2.0,
        "arena_centre_m": [L / 2.0, L / 2.0],
        "count": 5.0,
    }


def split_obs(obs: torch.Tensor, ctde: bool) -> tuple[torch.Tensor, torch.Tensor | None, int]:
    """``(own observation, critic entries or None, N − 1)`` of flat observations ``(R, D)``."""
    per = SLOT_SIZE + (STATE_ENTRY if ctde else 0)
    m, rem = divmod(obs.shape[-1] - CUE_SIZE, per)
    if m < 0 or rem:
        raise ValueError(
            f"observation length must be {per} (N - 1) + {CUE_SIZE} (ctde={ctde}), "
            f"got {obs.shape[-1]}"
        )
    own = obs[..., : SLOT_SIZE * m + CUE_SIZE]
    if not ctde:
        return own, None, m
    return own, obs[..., SLOT_SIZE * m + CUE_SIZE :].reshape(*obs.shape[:-1], m, STATE_ENTRY), m


def _entry_features(slots: torch.Tensor, scale: float) -> tuple[torch.Tensor, torch.Tensor]:
    mask = (slots[..., SLOT_DETECTED] > 0.5).to(slots.dtype)
    xy = slots[..., SLOT_P_BODY] / scale
    d = torch.sqrt((xy * xy).sum(-1, keepdim=True))
    feat = torch.cat([xy, slots[..., SLOT_YAW_CS], d], dim=-1) * mask.unsqueeze(-1)
    return feat, mask


def _cue_features(cue: torch.Tensor, centre: torch.Tensor, half: float) -> torch.Tensor:
    q = cue[..., CUE_GOAL_BODY] / half
    return torch.cat(
        [
            (cue[..., CUE_P_WORLD] - centre) / half,
            cue[..., CUE_YAW_CS],
            q,
            torch.sqrt((q * q).sum(-1, keepdim=True)),
            cue[..., CUE_SCALAR, None] / half,
        ],
        dim=-1,
    )


def _mlp(n_in: int, widths: list[int], act: str) -> nn.Sequential:
    layers: list[nn.Module] = []
    for w in widths:
        layers += [nn.Linear(n_in, w), _ACT[act]()]
        n_in = w
    return nn.Sequential(*layers)


def _pool(e: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Masked mean and max over entries (dim -2) and the count; max is 0 for none."""
    count = mask.sum(-1, keepdim=True)
    mean = (e * mask.unsqueeze(-1)).sum(-2) / count.clamp(min=1.0)
    if e.shape[-2] == 0:
        return mean, torch.zeros_like(mean), count
    big = e.masked_fill(mask.unsqueeze(-1) < 0.5, float("-inf")).amax(-2)
    return mean, torch.where(count > 0, big, torch.zeros_like(big)), count


class _SetEncoder(nn.Module):
    """The actor's network up to the head output (see :mod:`fov_marl.baselines.learned`)."""

    def __init__(self, hidden: int, act: str, scales: dict[str, Any]) -> None:
        super().__init__()
        self.phi = _mlp(NEIGHBOUR_FEATURES, [hidden, hidden], act)
        self.cue = _mlp(CUE_FEATURES, [hidden], act)
        self.head = _mlp(3 * hidden + 1, [hidden, hidden], act)
        self.neighbour_m = float(scales["neighbour_m"])
        self.half_m = float(scales["arena_half_m"])
        self.count_scale = float(scales["count"])
        self.register_buffer(
            "centre_m", torch.tensor(scales["arena_centre_m"], dtype=torch.float32)
        )

    def pooled(self, own: torch.Tensor, m: int) -> torch.Tensor:
        slots = own[..., : SLOT_SIZE * m].reshape(*own.shape[:-1], m, SLOT_SIZE)
        feat, mask = _entry_features(slots, self.neighbour_m)
        mean, mx, count = _pool(self.phi(feat), mask)
        c = self.cue(_cue_features(own[..., SLOT_SIZE * m :], self.centre_m, self.half_m))
        return torch.cat([mean, mx, c, count / self.count_scale], dim=-1)

    def forward(self, own: torch.Tensor, m: int) -> torch.Tensor:
        return self.head(self.pooled(own, m))


class SetActorCritic(nn.Module):
    """SB3 ``mlp_extractor``: ``forward_actor`` / ``forward_critic`` on the raw observation.

    Args:
        hidden: width of every layer (φ, ψ, head; the critic's too).
        activation: ``"tanh"`` or ``"relu"``.
        ctde: the observation carries the critic entries (module docstring).
        feature_scales: :func:`default_feature_scales` of the training scenario.
    """

    def __init__(
        self, hidden: int, activation: str, ctde: bool, feature_scales: dict[str, Any]
    ) -> None:
        super().__init__()
        self.ctde = bool(ctde)
        self.actor = _SetEncoder(hidden, activation, feature_scales)
        self.critic_local = _SetEncoder(hidden, activation, feature_scales)
        n_in = 3 * hidden + 1
        if self.ctde:
            self.critic_state = _mlp(NEIGHBOUR_FEATURES, [hidden, hidden], activation)
            self.state_scale = float(feature_scales["arena_half_m"])
            n_in += 2 * hidden
        self.critic_head = _mlp(n_in, [hidden, hidden], activation)
        self.latent_dim_pi = hidden
        self.latent_dim_vf = hidden

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        own, _, m = split_obs(features, self.ctde)
        return self.actor(own, m)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        own, state, m = split_obs(features, self.ctde)
        parts = [self.critic_local.pooled(own, m)]
        if state is not None:
            feat, mask = _entry_features(state, self.state_scale)
            mean, mx, _ = _pool(self.critic_state(feat), mask)
            parts += [mean, mx]
        return self.critic_head(torch.cat(parts, dim=-1))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)


class SetActorCriticPolicy(ActorCriticPolicy):
    """``ActorCriticPolicy`` whose networks are :class:`SetActorCritic` (module docstring).

    Extra keyword arguments (``policy_kwargs``): ``hidden`` (64), ``set_activation``
    (``"tanh"``), ``ctde`` (False), ``feature_scales`` (required: the training
    scenario's :func:`default_feature_scales`), ``bounded_mean`` (the Gaussian's mean is
    ``tanh(A z + b)``, inside the action box, so penalties on the applied action keep a
    gradient; an unbounded mean drifts far outside ``[-1, 1]``, where every sample is
    clipped to the same action). Its default here is False so that models saved before
    the option load as they were; :func:`~fov_marl.training.train` passes True unless
    ``policy_kwargs={"bounded_mean": false}``.
    """

    def __init__(
        self,
        observation_space: gym.spaces.Space,
        action_space: gym.spaces.Space,
        lr_schedule: Any,
        *args: Any,
        hidden: int = 64,
        set_activation: str = "tanh",
        ctde: bool = False,
        feature_scales: dict[str, Any] | None = None,
        bounded_mean: bool = False,
        **kwargs: Any,
    ) -> None:
        if feature_scales is None:
            raise ValueError("feature_scales is required (default_feature_scales(config))")
        if set_activation not in _ACT:
            raise ValueError(
                f"set_activation must be one of {sorted(_ACT)}, got {set_activation!r}"
            )
        self.hidden = int(hidden)
        self.set_activation = set_activation
        self.ctde = bool(ctde)
        self.feature_scales = dict(feature_scales)
        self.bounded_mean = bool(bounded_mean)
        kwargs.pop("net_arch", None)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        if self.bounded_mean:  # same parameters (the optimizer already holds them)
            self.action_net = nn.Sequential(self.action_net, nn.Tanh())

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = SetActorCritic(
            self.hidden, self.set_activation, self.ctde, self.feature_scales
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            hidden=self.hidden,
            set_activation=self.set_activation,
            ctde=self.ctde,
            feature_scales=self.feature_scales,
            bounded_mean=self.bounded_mean,
        )
        return data


def actor_weights(policy: SetActorCriticPolicy) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(weights, config)`` of the actor, for :class:`fov_marl.baselines.learned.SetActorWeights`.

    Weight names follow the numpy module's (``phi.<k>.weight``: the k-th Linear of φ).
    """
    enc = policy.mlp_extractor.actor
    weights: dict[str, np.ndarray] = {}
    for prefix, seq in (("phi", enc.phi), ("cue", enc.cue), ("head", enc.head)):
        linears = [m for m in seq if isinstance(m, nn.Linear)]
        for k, lin in enumerate(linears):
            weights[f"{prefix}.{k}.weight"] = lin.weight.detach().cpu().numpy().astype(np.float32)
            weights[f"{prefix}.{k}.bias"] = lin.bias.detach().cpu().numpy().astype(np.float32)
    lin = policy.action_net[0] if policy.bounded_mean else policy.action_net
    weights["action.weight"] = lin.weight.detach().cpu().numpy().astype(np.float32)
    weights["action.bias"] = lin.bias.detach().cpu().numpy().astype(np.float32)
    weights["log_std"] = policy.log_std.detach().cpu().numpy().astype(np.float32)
    config = {
        "format": MODEL_FORMAT,
        "arch": {
            "hidden": policy.hidden,
            "activation": policy.set_activation,
            "bounded_mean": policy.bounded_mean,
        },
        "feature_scales": dict(policy.feature_scales),
    }
    return weights, config


# ------------------------------------------------------------ CTDE + reward shaping
def agent_centric_state(obs: np.ndarray) -> np.ndarray:
    """``(B, N, 5 (N − 1))`` critic entries (module docstring) from observations ``(B, N, D)``.

    Robot k's exact world pose is in its cue (entries ``5 (N − 1) + 0..3``), so the
    global state of a copy is a function of its robots' observations.
    """
    obs = np.asarray(obs, dtype=np.float64)
    B, N, _ = obs.shape
    m = N - 1
    cue = obs[..., SLOT_SIZE * m :]
    p, c, s = cue[..., CUE_P_WORLD], cue[..., CUE_YAW_CS][..., 0], cue[..., CUE_YAW_CS][..., 1]
    d = p[:, None, :, :] - p[:, :, None, :]  # (B, i, k, 2) world, p_k - p_i
    ci, si = c[:, :, None], s[:, :, None]
    ck, sk = c[:, None, :], s[:, None, :]
    xb = ci * d[..., 0] + si * d[..., 1]
    yb = -si * d[..., 0] + ci * d[..., 1]
    ent = np.stack(
        [np.ones_like(xb), xb, yb, ck * ci + sk * si, sk * ci - ck * si], axis=-1
    )  # (B, i, k, 5)
    others = np.array([[k for k in range(N) if k != i] for i in range(N)], dtype=np.int64)
    if m == 0:
        return np.zeros((B, N, 0), dtype=np.float32)
    ent = ent[:, np.arange(N)[:, None], others]  # (B, N, N-1, 5)
    return ent.reshape(B, N, m * STATE_ENTRY).astype(np.float32)


class CtdeVecEnvWrapper(VecEnvWrapper):
    """Training-only VecEnv layer: CTDE critic entries and reward shaping, per slot.

    Sits on the parameter-sharing adapter (slot ``s`` = robot ``s % N`` of copy
    ``s // N``; both adapters of :mod:`fov_marl.training.vec_env`) and below
    ``VecMonitor``, so SB3's ``ep_rew_mean`` is the shaped return it optimises
    (``fov/*`` scalars stay the env's ground-truth metrics).

    ================================  ==============================================
    term (added to the env reward)     meaning
    ================================  ==============================================
    ``eta_level_coef · g(η)``          ``g(η) = −log10(1 − η + 1e−4) / 4`` in [0, 1]:
                                       a per-step reward for the coverage level that
                                       resolves the last per mille (0.99 -> 0.50,
                                       0.996 -> 0.60, 0.9999 -> 0.92); the env's own
                                       reward is the η *gain*, which vanishes once a
                                       formation holds
    ``− intervention_coef · ‖Δu‖``     behind the safety filter: Δu = applied −
                                       nominal velocity, normalised (v / v_max, ω /
                                       ω_max), so the policy learns actions the filter
                                       leaves alone
    ``− blind_motion_coef · b(a)``     ``b = ‖v‖ · max(0, |∠v| − β / 2) / π``: planar
                                       speed (normalised) towards directions outside
                                       the camera's sector. No filter needed: it
                                       teaches "look where you drive" before training
                                       behind the filter, whose blind-travel rows slow
                                       (and count as interventions) motion into space
                                       the robot has not looked at
    ``− action_cost_coef · e(a)``      ``e = (‖v‖² + ω²) / 2`` (normalised, in [0, 1]):
                                       holding a formation by standing still rather
                                       than by circling at full speed (which the
                                       filter's rows keep correcting)
    ``− fov_keep_coef · k``            ``k = Σ_j [d_ij < 3 D_s] max(0, |∠ⁱp_j| − β/2)
                                       / π`` (exact positions, as the critic's): close
                                       neighbours outside the camera sector, which the
                                       filter's FoV rows (slack ``σ(d − 3 D_s)``, Eq.
                                       16) would turn the camera to
    ================================  ==============================================

    Args:
        venv: the adapter.
        n_agents: N.
        ctde: append :func:`agent_centric_state` to every observation (and to
            ``terminal_observation``).
        eta_level_coef, intervention_coef, blind_motion_coef: the shaping weights (0
            disables a term).
        action_cost_coef, fov_keep_coef: see the table.
        fov_deg: β of the scenario (``blind_motion_coef``, ``fov_keep_coef``).
        keep_distance_m: 3 D_s of the scenario (``fov_keep_coef``).
    """

    def __init__(
        self,
        venv: VecEnv,
        n_agents: int,
        *,
        ctde: bool = False,
        eta_level_coef: float = 0.0,
        intervention_coef: float = 0.0,
        blind_motion_coef: float = 0.0,
        fov_deg: float = 120.0,
        action_cost_coef: float = 0.0,
        fov_keep_coef: float = 0.0,
        keep_distance_m: float = 6.0,
    ) -> None:
        self.n_agents = int(n_agents)
        self.action_cost_coef = float(action_cost_coef)
        self.fov_keep_coef = float(fov_keep_coef)
        self.keep_distance_m = float(keep_distance_m)
        self.blind_motion_coef = float(blind_motion_coef)
        self.fov_half_rad = np.deg2rad(float(fov_deg)) / 2.0
        self._actions: np.ndarray | None = None
        self.ctde = bool(ctde)
        self.eta_level_coef = float(eta_level_coef)
        self.intervention_coef = float(intervention_coef)
        space = venv.observation_space
        if self.ctde:
            extra = STATE_ENTRY * (self.n_agents - 1)
            lim = np.full(extra, 1e3, dtype=np.float32)
            space = gym.spaces.Box(
                np.concatenate([space.low, -lim]).astype(np.float32),
                np.concatenate([space.high, lim]).astype(np.float32),
                dtype=np.float32,
            )
        super().__init__(venv, observation_space=space)

    def _augment(self, obs: np.ndarray) -> np.ndarray:
        if not self.ctde:
            return obs
        N = self.n_agents
        o = np.asarray(obs, dtype=np.float32).reshape(-1, N, obs.shape[-1])
        st = agent_centric_state(o)
        return np.concatenate([o, st], axis=-1).reshape(o.shape[0] * N, -1)

    def reset(self) -> np.ndarray:
        return self._augment(self.venv.reset())

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)
        self.venv.step_async(actions)

    def step_wait(self) -> Any:
        obs, rew, dones, infos = self.venv.step_wait()
        rew = np.asarray(rew, dtype=np.float32).copy()
        if self.eta_level_coef:
            eta = np.array([float(i.get(METRICS_PREFIX + "eta", 0.0)) for i in infos])
            rew += (self.eta_level_coef * eta_level_reward(eta)).astype(np.float32)
        if self.intervention_coef and infos and "safety/applied_action" in infos[0]:
            nom = np.stack([np.asarray(i["safety/nominal_action"], np.float64) for i in infos])
            app = np.stack([np.asarray(i["safety/applied_action"], np.float64) for i in infos])
            rew -= (self.intervention_coef * action_change(nom, app)).astype(np.float32)
        if self.blind_motion_coef and self._actions is not None:
            rew -= (self.blind_motion_coef * blind_motion(self._actions, self.fov_half_rad)).astype(
                np.float32
            )
        if self.action_cost_coef and self._actions is not None:
            rew -= (self.action_cost_coef * action_energy(self._actions)).astype(np.float32)
        if self.fov_keep_coef and self.n_agents > 1:
            N = self.n_agents
            st = agent_centric_state(np.asarray(obs).reshape(-1, N, obs.shape[-1]))
            cost = fov_keep_cost(
                st.reshape(-1, N - 1, STATE_ENTRY), self.fov_half_rad, self.keep_distance_m
            )
            rew -= (self.fov_keep_coef * cost).astype(np.float32)
        if self.ctde and np.any(dones):
            N = self.n_agents
            idx = np.flatnonzero(dones)
            copies = np.unique(idx // N)
            term = np.stack(
                [infos[c * N + i]["terminal_observation"] for c in copies for i in range(N)]
            ).reshape(len(copies), N, -1)
            aug = np.concatenate([term, agent_centric_state(term)], axis=-1)
            for a, c in enumerate(copies.tolist()):
                for i in range(N):
                    infos[c * N + i]["terminal_observation"] = aug[a, i]
        return self._augment(obs), rew, dones, infos


def eta_level_reward(eta: np.ndarray) -> np.ndarray:
    """``g(η) = −log10(1 − η + 1e−4) / 4`` (see :class:`CtdeVecEnvWrapper`)."""
    gap = np.clip(1.0 - np.asarray(eta, dtype=np.float64), 0.0, 1.0)
    return -np.log10(gap + 1e-4) / 4.0


def action_change(nominal: np.ndarray, applied: np.ndarray) -> np.ndarray:
    """``(R,)`` ‖applied − nominal‖ in normalised velocity units (the env's planar speed
    limit applied to the nominal action first, as the filter does)."""
    a = np.clip(np.asarray(nominal, dtype=np.float64), -1.0, 1.0)
    v = a[..., :2]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    v = v * np.minimum(1.0, 1.0 / np.maximum(n, 1e-12))
    u = np.concatenate([v, a[..., 2:3]], axis=-1)
    return np.linalg.norm(np.asarray(applied, dtype=np.float64) - u, axis=-1)


def blind_motion(actions: np.ndarray, fov_half_rad: float) -> np.ndarray:
    """``(R,)`` ``‖v‖ · max(0, |∠v| − β / 2) / π`` of actions ``(R, 3)`` (normalised planar
    speed, clipped as the env does, times its angle outside the camera sector)."""
    a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
    speed = np.minimum(np.linalg.norm(a[..., :2], axis=-1), 1.0)
    out = np.maximum(np.abs(np.arctan2(a[..., 1], a[..., 0])) - fov_half_rad, 0.0) / np.pi
    return speed * out


def action_energy(actions: np.ndarray) -> np.ndarray:
    """``(R,)`` ``(‖v‖² + ω²) / 2`` of actions ``(R, 3)`` (planar speed clipped to 1)."""
    a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
    speed = np.minimum(np.linalg.norm(a[..., :2], axis=-1), 1.0)
    return 0.5 * (speed**2 + a[..., 2] ** 2)


def fov_keep_cost(entries: np.ndarray, fov_half_rad: float, keep_distance_m: float) -> np.ndarray:
    """``(R,)`` ``Σ_j [d_ij < keep] max(0, |∠ⁱp_j| − β/2) / π`` from critic entries
    ``(R, N − 1, 5)`` (:func:`agent_centric_state`)."""
    e = np.asarray(entries, dtype=np.float64)
    d = np.hypot(e[..., 1], e[..., 2])
    out = np.maximum(np.abs(np.arctan2(e[..., 2], e[..., 1])) - fov_half_rad, 0.0) / np.pi
    return np.sum((e[..., 0] > 0.5) * (d < keep_distance_m) * out, axis=-1)
