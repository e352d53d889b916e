"""``make_policy("learned", env)``: the shipped, size-independent learned coverage policy.

A numpy forward pass (no torch) of the actor trained by
:mod:`fov_marl.training.set_policy` and exported with
:func:`fov_marl.training.export_policy`. One set of weights runs for any team size N:
each robot reads its own observation only (decentralised execution), parsed as a *set*
of ``N − 1`` neighbour entries and its own cue; the entries go through one shared MLP
φ, are pooled by masked mean and max (undetected slots are masked out, so they have no
effect), and the pooled vectors, the count of detections and the encoded cue feed the
action head. Permuting the neighbour slots leaves the action unchanged.

The shipped model was trained behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`,
and ``fov-marl evaluate --policy learned`` / ``render`` run it behind the filter
(:func:`trained_filter`; so do an exported folder and a ``model.zip`` trained behind
the filter). In Python, wrap the env yourself
(``SafetyFilterWrapper(env)``, or ``run_episode(..., safety_filter=True)``): alone, it
collides. Measured without the filter, N = 6, 20 seeds: collisions in every episode.
With it: 0 collisions, and final η about pfcbf's (README, "Learned policy").

>>> from fov_marl.baselines import make_policy
>>> policy = make_policy("learned", env)                 # the shipped model, any N
>>> policy = make_policy("learned", env, path="runs/set/export")   # a user's export
>>> policy.reset(seed=0); actions = policy.act(obs)      # deterministic

Features (the single definition; the torch actor computes the same, tested to 1e-5)
-----------------------------------------------------------------------------------
Metres are divided by *fixed* constants stored in the model's ``config.json``
(``feature_scales``), never by running statistics, which would be tied to slot index
and to N.

Neighbour entry (one per slot ``k`` of the observation, 5 features, all zero when the
slot is not detected):

=====  ============================  =====================================
index  feature                       from observation entries
=====  ============================  =====================================
0, 1   ⁱx_j / s_n, ⁱy_j / s_n        ``5k + 1``, ``5k + 2`` (m, Σ_i)
2, 3   cos, sin of θ_j − θ_i         ``5k + 3``, ``5k + 4``
4      ‖ⁱp_j‖ / s_n                  —
=====  ============================  =====================================

``s_n = neighbour_m`` (the detection range R_d of the training scenario, 10 m); the
mask is the detected flag ``5k + 0``.

Cue (8 features): ``(x − c_x) / h``, ``(y − c_y) / h`` (own world position about the
arena centre c, h = half the arena side), cos and sin of the own yaw, ⁱq_m / h (2),
‖ⁱq_m‖ / h, σ / h.

Network (sizes in ``config.json`` ``arch``; activation tanh)
------------------------------------------------------------
``e_k = φ(neighbour_k)`` (2 layers of ``hidden``), ``mean = Σ m_k e_k / max(Σ m_k, 1)``,
``max = max_{m_k = 1} e_k`` (0 when nothing is detected), ``c = ψ(cue)`` (1 layer),
``z = head([mean, max, c, Σ m_k / count_scale])`` (2 layers), action mean ``= tanh(A z +
b)`` (``arch.bounded_mean``; ``A z + b`` without it). The deterministic action is that
mean clipped to ``[-1, 1]`` (the Gaussian's log-std is stored but unused).

Files of a model folder
-----------------------
=================  ===============================================================
``weights.npz``    float32 arrays named ``phi.<k>.weight`` / ``.bias`` (``(out, in)``
                   as torch stores them), ``cue.0.*``, ``head.<k>.*``, ``action.*``,
                   ``log_std``
``config.json``    ``format`` (``"fov_marl.set_policy/1"``), ``arch``,
                   ``feature_scales``, the training config and the command that
                   produced it (see the README, "Learned policy")
=================  ===============================================================
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from fov_marl.baselines.registry import register_policy
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
from fov_marl.validation import check_bool, check_real, check_real_sequence, check_seed, describe

__all__ = [
    "MODEL_FORMAT",
    "SHIPPED_MODEL",
    "SetActorWeights",
    "LearnedSetPolicy",
    "n_slots_of",
    "neighbour_features",
    "cue_features",
    "shipped_model_dir",
    "trained_filter",
]

MODEL_FORMAT = "fov_marl.set_policy/1"
#: folder name of the shipped model inside the package (``fov_marl/models/``)
SHIPPED_MODEL = "learned_coverage"
NEIGHBOUR_FEATURES = 5
CUE_FEATURES = 8


def shipped_model_dir() -> Path:
    """The folder of the shipped pretrained model (``fov_marl/models/learned_coverage``)."""
    return Path(str(resources.files("fov_marl").joinpath("models", SHIPPED_MODEL)))


def trained_filter(path: str | os.PathLike | None = None) -> tuple[bool, dict | None]:
    """``(safety_filter, safety_filter_kwargs)`` a model folder was trained with.

    Read from its ``config.json`` ``training`` entry (:func:`fov_marl.training.export_policy`
    stores the training config there); ``(False, None)`` when it records none. The CLI
    (``fov-marl evaluate`` / ``render``) runs such a model behind its filter, as it does
    a trained ``model.zip``.

    Args:
        path: a model folder; default the shipped model.
    """
    d = Path(path) if path is not None else shipped_model_dir()
    try:
        config = json.loads((d / "config.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False, None
    training = config.get("training") if isinstance(config, dict) else None
    if not isinstance(training, dict) or not training.get("safety_filter"):
        return False, None
    kw = training.get("safety_filter_kwargs")
    return True, dict(kw) if isinstance(kw, dict) and kw else None


def n_slots_of(obs_dim: int, extra_per_slot: int = 0) -> int:
    """Neighbour slots ``N − 1`` of a flat observation of length ``obs_dim``.

    ``obs_dim = (5 + extra_per_slot) (N − 1) + 7`` (``extra_per_slot = 5`` for the CTDE
    training observation, which appends the critic's state entries).

    Raises:
        ValueError: ``obs_dim`` is not of that form.
    """
    per = SLOT_SIZE + int(extra_per_slot)
    m, rem = divmod(int(obs_dim) - CUE_SIZE, per)
    if m < 0 or rem:
        raise ValueError(
            f"observation length must be {per} (N - 1) + {CUE_SIZE} for some N >= 1, got {obs_dim}"
        )
    return m


def neighbour_features(slots: np.ndarray, scale_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``(features (..., M, 5), mask (..., M) float)`` of neighbour slots ``(..., M, 5)``.

    Entry 0 of a slot is the presence flag (detected / present); undetected slots give
    all-zero features and mask 0 (module docstring, "Features").
    """
    slots = np.asarray(slots, dtype=np.float64)
    mask = (slots[..., SLOT_DETECTED] > 0.5).astype(np.float64)
    xy = slots[..., SLOT_P_BODY] / scale_m
    d = np.sqrt(np.sum(xy * xy, axis=-1, keepdims=True))
    feat = np.concatenate([xy, slots[..., SLOT_YAW_CS], d], axis=-1) * mask[..., None]
    return feat, mask


def cue_features(cue: np.ndarray, centre_m: np.ndarray, half_m: float) -> np.ndarray:
    """``(..., 8)`` cue features of cues ``(..., 7)`` (module docstring, "Features")."""
    cue = np.asarray(cue, dtype=np.float64)
    q = cue[..., CUE_GOAL_BODY] / half_m
    return np.concatenate(
        [
            (cue[..., CUE_P_WORLD] - np.asarray(centre_m, dtype=np.float64)) / half_m,
            cue[..., CUE_YAW_CS],
            q,
            np.sqrt(np.sum(q * q, axis=-1, keepdims=True)),
            cue[..., CUE_SCALAR, None] / half_m,
        ],
        axis=-1,
    )


def _act(name: str, x: np.ndarray) -> np.ndarray:
    if name == "tanh":
        return np.tanh(x)
    if name == "relu":
        return np.maximum(x, 0.0)
    raise ValueError(f"arch.activation must be one of ['relu', 'tanh'], got {name!r}")


def _check_format(config: Any, where: str) -> dict[str, Any]:
    if not isinstance(config, dict) or config.get("format") != MODEL_FORMAT:
        got = config.get("format") if isinstance(config, dict) else type(config).__name__
        raise ValueError(f"{where}: format must be {MODEL_FORMAT!r}, got {got!r}")
    for key in ("arch", "feature_scales"):
        if not isinstance(config.get(key), dict):
            raise ValueError(f"{where}: {key} must be a JSON object")
    return config


def _scale(where: str, scales: dict[str, Any], key: str, default: float | None = None) -> float:
    """``feature_scales[key]``: a finite real > 0 (a divisor of the features)."""
    if key not in scales:
        if default is not None:
            return default
        raise ValueError(f"{where}: feature_scales.{key} is missing (a length in metres > 0)")
    try:
        return check_real(f"feature_scales.{key}", scales[key], 0.0, lo_open=True)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _weight_array(where: str, name: str, value: Any) -> np.ndarray:
    """A weight as float64: a numeric array of finite values (naming it otherwise)."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{where}: {name} must be a numeric array, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(
            f"{where}: {name} must be finite, got {bad} non-finite value(s) (NaN or inf) "
            f"of {arr.size}"
        )
    return arr


class SetActorWeights:
    """The exported actor: weights and config, with a vectorised numpy forward pass.

    Args:
        weights: name -> array (``weights.npz``, module docstring); every array numeric
            and finite (NaN or inf would make every action NaN).
        config: the model's ``config.json`` contents; ``feature_scales.neighbour_m``,
            ``arena_half_m`` (finite, > 0) and ``arena_centre_m`` (2 finite reals) are
            required, ``count`` (finite, > 0) defaults to 5; ``arch.activation``
            (``"tanh"``/``"relu"``, default tanh) and ``arch.bounded_mean`` (a bool,
            default False) are optional.
        where_weights, where_config: how messages name the two (:meth:`load` passes the
            files' paths).

    Raises:
        ValueError: a missing, mis-shaped or non-finite weight, a missing or invalid
            feature scale, or a config of another format (naming the file and field).
    """

    def __init__(
        self,
        weights: dict[str, np.ndarray],
        config: dict[str, Any],
        *,
        where_weights: str = "weights",
        where_config: str = "config",
    ) -> None:
        self._where_w = where_weights
        self.config = _check_format(config, where_config)
        if not isinstance(weights, dict):
            raise ValueError(f"{where_weights}: must be a dict of arrays, got {describe(weights)}")
        arch = config["arch"]
        self.activation: str = arch.get("activation", "tanh")
        if self.activation not in ("relu", "tanh"):
            raise ValueError(
                f"{where_config}: arch.activation must be one of ['relu', 'tanh'], "
                f"got {describe(self.activation)}"
            )
        try:
            self.bounded_mean = check_bool("arch.bounded_mean", arch.get("bounded_mean", False))
        except ValueError as exc:
            raise ValueError(f"{where_config}: {exc}") from None
        scales = config["feature_scales"]
        self.neighbour_m = _scale(where_config, scales, "neighbour_m")
        self.half_m = _scale(where_config, scales, "arena_half_m")
        if "arena_centre_m" not in scales:
            raise ValueError(
                f"{where_config}: feature_scales.arena_centre_m is missing (the arena centre "
                "[x, y] in metres)"
            )
        try:
            centre = check_real_sequence(
                "feature_scales.arena_centre_m", scales["arena_centre_m"], 2
            )
        except ValueError as exc:
            raise ValueError(f"{where_config}: {exc}") from None
        self.centre_m = np.asarray(centre, dtype=np.float64)
        self.count_scale = _scale(where_config, scales, "count", 5.0)
        self.w = {}
        for k, v in weights.items():
            if not isinstance(k, str):
                raise ValueError(f"{where_weights}: weight names must be strings, got {k!r}")
            self.w[k] = _weight_array(where_weights, k, v)
        self.phi = self._layers("phi")
        self.cue = self._layers("cue")
        self.head = self._layers("head")
        if "action.weight" not in self.w or "action.bias" not in self.w:
            raise ValueError(f"{where_weights}: action.weight and action.bias are required")
        self.action = (self.w["action.weight"], self.w["action.bias"])
        hid = self.phi[-1][0].shape[0]
        want_in = {
            "phi": NEIGHBOUR_FEATURES,
            "cue": CUE_FEATURES,
            "head": 2 * hid + self.cue[-1][0].shape[0] + 1,
        }
        for name, layers in (("phi", self.phi), ("cue", self.cue), ("head", self.head)):
            if layers[0][0].shape[1] != want_in[name]:
                raise ValueError(
                    f"{where_weights}: {name}.0.weight must take {want_in[name]} inputs, "
                    f"got shape {layers[0][0].shape}"
                )
        if self.action[0].shape != (3, self.head[-1][0].shape[0]):
            raise ValueError(
                f"{where_weights}: action.weight must have shape "
                f"{(3, self.head[-1][0].shape[0])}, got {self.action[0].shape}"
            )
        if self.action[1].shape != (3,):
            raise ValueError(
                f"{where_weights}: action.bias must have shape (3,), got {self.action[1].shape}"
            )

    def _layers(self, prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
        where = self._where_w
        out = []
        k = 0
        while f"{prefix}.{k}.weight" in self.w:
            W, b = self.w[f"{prefix}.{k}.weight"], self.w.get(f"{prefix}.{k}.bias")
            if W.ndim != 2 or b is None or b.shape != (W.shape[0],):
                raise ValueError(
                    f"{where}: {prefix}.{k} must be a (out, in) weight and (out,) bias"
                )
            if out and W.shape[1] != out[-1][0].shape[0]:
                raise ValueError(f"{where}: {prefix}.{k}.weight does not chain onto layer {k - 1}")
            out.append((W, b))
            k += 1
        if not out:
            raise ValueError(f"{where}: no {prefix}.0.weight")
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> SetActorWeights:
        """Load a model folder holding ``weights.npz`` and ``config.json``.

        Raises:
            ValueError: a missing or unreadable file (truncated, corrupted, not an
                ``.npz``), or invalid contents (:class:`SetActorWeights`); the message
                names the file and the field.
        """
        if not isinstance(path, str | os.PathLike):
            raise ValueError(
                f"path must be a model folder (str or os.PathLike), got {describe(path)}"
            )
        d = Path(path)
        cfg_path, w_path = d / "config.json", d / "weights.npz"
        for p in (cfg_path, w_path):
            if not p.is_file():
                raise ValueError(f"learned policy folder {d}: {p.name} does not exist")
        try:
            config = json.loads(cfg_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{cfg_path}: not a readable JSON file ({exc})") from None
        _check_format(config, str(cfg_path))
        try:
            z = np.load(w_path, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):  # a bare .npy array
                raise ValueError("a single array, not an .npz archive of named arrays")
            with z:
                weights = {k: z[k] for k in z.files}
        except (
            OSError,
            ValueError,
            EOFError,
            KeyError,
            NotImplementedError,
            zipfile.BadZipFile,
            zlib.error,
        ) as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise ValueError(f"{w_path}: not a readable .npz file ({reason})") from None
        return cls(weights, config, where_weights=str(w_path), where_config=str(cfg_path))

    def _mlp(self, layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
        for W, b in layers:
            x = _act(self.activation, x @ W.T + b)
        return x

    def latent(self, obs: np.ndarray) -> np.ndarray:
        """``(R, hidden)`` head output for flat observations ``(R, 5 (N − 1) + 7)``."""
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim != 2:
            raise ValueError(f"obs must have shape (robots, obs_dim), got {obs.shape}")
        m = n_slots_of(obs.shape[1])
        slots = obs[:, : SLOT_SIZE * m].reshape(len(obs), m, SLOT_SIZE)
        feat, mask = neighbour_features(slots, self.neighbour_m)
        e = self._mlp(self.phi, feat)  # (R, M, H)
        count = mask.sum(axis=1, keepdims=True)  # (R, 1)
        mean = np.einsum("rmh,rm->rh", e, mask) / np.maximum(count, 1.0)
        big = np.where(mask[..., None] > 0, e, -np.inf)
        mx = big.max(axis=1) if m else np.zeros_like(mean)
        mx = np.where(count > 0, mx, 0.0)
        c = self._mlp(self.cue, cue_features(obs[:, SLOT_SIZE * m :], self.centre_m, self.half_m))
        return self._mlp(self.head, np.concatenate([mean, mx, c, count / self.count_scale], 1))

    def mean_action(self, obs: np.ndarray) -> np.ndarray:
        """``(R, 3)`` mean of the policy's Gaussian for observations ``(R, obs_dim)``."""
        W, b = self.action
        mean = self.latent(obs) @ W.T + b
        return np.tanh(mean) if self.bounded_mean else mean

    def act(self, obs: np.ndarray) -> np.ndarray:
        """``(R, 3)`` float32 deterministic actions: the mean clipped to ``[-1, 1]``."""
        return np.clip(self.mean_action(obs), -1.0, 1.0).astype(np.float32)


class LearnedSetPolicy:
    """A team policy running :class:`SetActorWeights` for every robot (Policy protocol).

    Each robot's action depends on its own observation only; the whole team is one
    batched forward pass. Stateless and deterministic (``reset`` only records the seed).

    Args:
        env: the env the policy acts in (any N). Its observations must have the fov
            layout, ``5 (N − 1) + 7`` entries for the ``N = env.unwrapped.config.n_agents``
            robots: a wrapper that appends entries (``BeliefObservationWrapper``) is
            refused, as the policy would read them as extra neighbour slots.
        path: a model folder (``weights.npz`` + ``config.json``); default the shipped
            model (:func:`shipped_model_dir`).

    Raises:
        ValueError: an unreadable or invalid model folder (:meth:`SetActorWeights.load`),
            an observation layout the policy cannot read, or a vector env (the message
            says how to run the actor on a batch); ``reset`` with a seed that is not
            None or an integer ≥ 0.
    """

    def __init__(self, env: Any, path: str | os.PathLike | None = None) -> None:
        if path is not None and not isinstance(path, str | os.PathLike):
            raise ValueError(
                f"path must be a model folder (str or os.PathLike) or None, got {describe(path)}"
            )
        if hasattr(env, "num_envs") or hasattr(getattr(env, "unwrapped", None), "num_envs"):
            raise ValueError(
                "the learned policy acts in one env (a ParallelEnv, possibly wrapped), got the "
                f"vector env {type(env).__name__}; for B copies run its actor on the batch: "
                "policy.model.act(obs.reshape(-1, obs.shape[-1]))"
            )
        self.model_dir = Path(path) if path is not None else shipped_model_dir()
        self.model = SetActorWeights.load(self.model_dir)
        self.config = self.model.config
        base = getattr(env, "unwrapped", env)
        self.agents = list(getattr(base, "possible_agents", []))
        space = env.observation_space(self.agents[0]) if self.agents else None
        if space is not None:
            dim = int(np.prod(space.shape))
            n_agents = getattr(getattr(base, "config", None), "n_agents", None)
            if isinstance(n_agents, int) and not isinstance(n_agents, bool):
                want = SLOT_SIZE * (n_agents - 1) + CUE_SIZE
                if dim != want:
                    raise ValueError(
                        f"the learned policy reads the fov observation layout, "
                        f"{SLOT_SIZE} (N - 1) + {CUE_SIZE} = {want} entries for n_agents = "
                        f"{n_agents}, but {type(env).__name__}'s observations have {dim} "
                        "(a wrapper that changes observations, e.g. BeliefObservationWrapper, "
                        "cannot be used with it)"
                    )
            else:
                n_slots_of(dim)
        self._seed: int | None = None

    def reset(self, seed: int | None = None) -> None:
        self._seed = check_seed("seed", seed)

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        agents = list(obs)
        if not agents:
            return {}
        batch = np.stack([np.asarray(obs[a], dtype=np.float32) for a in agents])
        act = self.model.act(batch)
        return {a: act[i] for i, a in enumerate(agents)}


@register_policy("learned")
def _make_learned(env: Any, path: str | os.PathLike | None = None) -> LearnedSetPolicy:
    return LearnedSetPolicy(env, path=path)
