"""Adversarial stress sweeps of the safety filter: ``fov-marl stress``.

A *case* is one adversary (:mod:`fov_marl.adversaries`) driving a team of N robots
with camera amplitude β from one kind of start, behind
:class:`~fov_marl.wrappers.SafetyFilterWrapper` or not, optionally with env/filter
overrides (:class:`StressCase`). :func:`run_stress` runs ``episodes`` seeded
episodes of ``steps`` steps per case and reports, per case:

==========================  ====================================================================
key                         meaning
==========================  ====================================================================
``collisions``              collision events (a pair entering contact, centres closer than
                            ``2 robot_radius_m``; the env's ``metrics["collisions_total"]``),
                            summed over episodes
``collision_episodes``      episodes with at least one collision event
``collision_seeds``         their seeds (rerun one with the same case and that seed)
``violation_events``        D_s violation events (``metrics["safety_violations_total"]``)
``violation_events_after_start``  the D_s events after the start: ``violation_events``
                            less the pairs already inside D_s at the start (the env counts
                            those as events at ``reset``). A packed start's pairs are
                            inside D_s from the first step; this counts only a pair entering
                            D_s during the episode (also one that started inside, left and
                            came back)
``violation_robot_steps``   robot-steps in which the robot is closer than D_s to some teammate
                            (ground truth ``env.unwrapped.poses``, after each step)
``min_distance_m``          smallest pairwise centre distance over all episodes (m),
                            ``metrics["min_distance_episode"]``, the start included;
                            None for a one-robot team (no pair; the env's metric is inf)
``start_min_distance_m``    smallest pairwise centre distance at the start over all episodes
                            (m); None for a one-robot team
``max_encroachment_m``      how much closer than it was owed any pair came, the largest over
                            all episodes (m): per pair ``min(start distance, D_s)`` less its
                            smallest distance (:func:`fov_marl.metrics.pair_encroachment`).
                            0 when every pair that started outside D_s kept D_s and every
                            packed pair kept its start distance; None for a one-robot team
``robot_steps``             robot-steps run (Σ over steps of the live robots)
``intervention_rate``       fraction of robot-steps with ``infos[a]["safety/intervened"]``
``mean_action_change``      mean over robot-steps of ‖u − u*‖₂ in action units (the
                            ``applied_action`` − ``nominal_action`` difference, a 3-vector
                            of normalised ``[vx, vy, ω]``)
``fallbacks``               robot-steps with ``infos[a]["safety/fallback"]``
``statuses``                robot-steps per filter ``status`` string
``intervention_causes``     share of robot-steps changed for each cause of
                            :data:`fov_marl.infos.SAFETY_CAUSES` (``safety/cause_bits``; a
                            step may have several); the table's ``top_cause`` is the largest
``chatter_rate``            period-2 sign flips of the applied action components per robot-step
                            (:func:`fov_marl.metrics.action_chatter`: ``+, −, +`` on three
                            consecutive steps, all above 0.05 in action units); the filter's
                            output when filtered, the adversary's action otherwise
``filter_chatter_rate``     the flips of ``chatter_rate`` the filter made: where the applied
                            component flips and the policy's own (nominal) one does not
                            (a chasing adversary steering at a noisy detection flips its
                            own ω; the filter passes that on)
==========================  ====================================================================

The six filter columns are ``None`` for unfiltered cases. Every number is a
deterministic function of the case and the seed: episode k of every case uses seed
``seed + k`` for the env and the filter (``env.reset(seed=seed + k)``), and child
seeds of it (``SeedSequence([seed + k, 1])`` / ``[seed + k, 2]``) for the start poses
and the adversary; ``workers > 1`` spreads the episodes over processes and gives
the same rows as ``workers=1``.

A long sweep can be stopped and resumed: with ``checkpoint=PATH`` (``fov-marl stress
--checkpoint PATH``) every finished episode is appended to ``PATH`` as one JSON line
(its case, seed, steps and measurements), and the episodes already there are not run
again. Since every number is a function of the case and the seed, a resumed sweep
gives the same rows as one that was never stopped (tested). A line holds the
``fov_marl`` version and a hash of the package's Python source that wrote it, less the
files that cannot change an episode (:func:`code_id`); a checkpoint from other code is
refused, because its episodes were measured on it (the version alone stays the same
across commits). Records are checked
entry by entry, and a file that is not a checkpoint is refused and left as it is.
:func:`stored_rows` gives the rows of the episodes stored so far, without running any;
``fov-marl stress --checkpoint`` prints them when it is stopped (Ctrl-C).

:func:`default_cases` gives the issue-10 acceptance grid (``full=True``) or a
representative small subset (``full=False``); :func:`format_stress_table` prints
rows; :func:`add_stress_parser` / :func:`cmd_stress` are the ``fov-marl stress``
command (``python -m fov_marl.stress`` runs it standalone).

Measured on the whole grid, one episode per case, after the blind travel budget per
bearing (commit cab1192, ``fov-marl stress --full --episodes 1 --seed 7000 --workers 2``,
29 min on 2 cores): 0 collision events in every case; no pair closer than its 1.1 m
packed start (min 1.1000 m); from random starts no D_s violation (min 2.26 m; by β
2.48 / 2.33 / 2.30 / 2.26 m at 45/90/120/360°) and none from ``head_on_pair`` (min
2.12 m). D_s was broken in 504 cases (8,388 events), all from starts inside D_s.
Robot-steps changed: 0.97 over all adversaries (0.94 from random starts; 0.995 / 0.993
/ 0.989 / 0.912 by β). Safe fallback: 0.089 of robot-steps from random starts. The
filter's own chatter: median 0.018 per robot-step, up to 0.126 at N = 24, β = 360°,
corner and clustered starts (packed, in the fallback; no budget rows exist at 360°).

Before it (commit 8d9d0bb, ``fov-marl stress
--full --episodes 1 --seed 7000 --workers 2``, 760 cases x 300 steps, 36 min on 2
cores): 0 collision events in every case. Pairs never got closer than 1.098 m, against
packed starts 1.1 m apart, so the known 2 mm dip below a packed start remains. D_s was
broken in 507 cases (8,391 events), almost all from starts already inside D_s
(clustered 2,484 events, corner 4,284, wall 1,620). From random starts there were 2
events (min 1.89 m), from ``head_on_pair`` 1 (min 1.93 m). Robot-steps changed: 0.96
over all adversaries (0.91 from random starts). Safe fallback: 0.13 of robot-steps from
random starts, 0.74-0.94 from packed ones (QPs infeasible while robots start inside each
other's D_s). By β the changed share is 0.98/0.98/0.98/0.91 at 45/90/120/360°.
Chatter was up to 0.36 per robot-step (``chase_last_seen``, ``wall_slide``; 0.67 for
``random``), almost all the adversaries' own flips: measured afterwards with
``filter_chatter_rate`` (one 300-step episode, seed 7000), 0.27 / 0.30 / 0.38 against
the filter's own 0.005 / 0.016 / 0.026 (``chase_last_seen`` N = 2, 360°, wall start and
N = 4, 360°, clustered; ``wall_slide`` N = 8, 360°, clustered).
"""

from __future__ import annotations

import argparse
import collections
import itertools
import os
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fov_marl.adversaries import (
    available_adversaries,
    available_starts,
    make_adversary,
    make_start_poses,
)
from fov_marl.infos import SAFETY_CAUSES, cause_counts, metrics_of, safety_of
from fov_marl.jsonio import write_json
from fov_marl.metrics import chatter_flips, pair_encroachment, pairwise_distances_batch
from fov_marl.stress_checkpoint import (
    CHECKPOINT_FORMAT,
    append_episode,
    code_id,
    episode_key,
    open_checkpoint,
    read_checkpoint,
)
from fov_marl.validation import (
    MAX_SEED,
    check_int,
    check_keys,
    check_out_path,
    check_writable,
    describe,
    keyword_parameters,
)

__all__ = [
    "StressCase",
    "run_stress",
    "run_stress_episode",
    "stored_rows",
    "code_id",
    "CHECKPOINT_FORMAT",
    "default_cases",
    "format_stress_table",
    "add_stress_parser",
    "cmd_stress",
    "FULL_N_AGENTS",
    "FULL_FOV_DEG",
    "FULL_STARTS",
    "STRESS_COLUMNS",
]

#: Team sizes, camera amplitudes (degrees) and starts of the acceptance grid (issue 10).
FULL_N_AGENTS: tuple[int, ...] = (2, 4, 8, 12, 24)
FULL_FOV_DEG: tuple[float, ...] = (45.0, 90.0, 120.0, 360.0)
FULL_STARTS: tuple[str, ...] = ("random", "clustered", "corner", "wall")
#: Adversaries also run from the ``head_on_pair`` start in the full grid.
HEAD_ON_PAIR_ADVERSARIES: tuple[str, ...] = ("straight", "head_on")

_SCENARIOS = ("coverage", "crossing")
_START_STREAM, _POLICY_STREAM = 1, 2


@dataclass(frozen=True)
class StressCase:
    """One cell of a stress sweep.

    Attributes:
        adversary: name from :func:`fov_marl.adversaries.available_adversaries`.
        n_agents: team size N (an integer >= 1, as the scenario config takes it).
        fov_deg: camera amplitude β in degrees, (0, 360].
        start: name from :func:`fov_marl.adversaries.available_starts`.
        filtered: run behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`.
        scenario: ``"coverage"`` or ``"crossing"``.
        env_kwargs: extra config fields for the env (not ``n_agents``, ``fov_deg``,
            ``max_cycles``, ``initial_poses``, which the case sets).
        filter_kwargs: keywords of ``SafetyFilterWrapper(env, **filter_kwargs)``
            (e.g. ``{"controller_params": {...}}``); only for a filtered case.
        adversary_kwargs: options of the adversary (``make_adversary(name, env, **kw)``).
        start_kwargs: options of the start (``make_start_poses(start, cfg, rng, **kw)``).

    Raises:
        ValueError: a field of the wrong type or out of its range (naming it): the four
            ``*_kwargs`` must be mappings with string keys, ``filter_kwargs`` only the
            filter's keywords; a filtered case whose env the filter refuses
            (:func:`~fov_marl.filter_options.check_filter_config`).
    """

    adversary: str
    n_agents: int
    fov_deg: float
    start: str = "random"
    filtered: bool = True
    scenario: str = "coverage"
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    filter_kwargs: Mapping[str, Any] = field(default_factory=dict)
    adversary_kwargs: Mapping[str, Any] = field(default_factory=dict)
    start_kwargs: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.adversary, str) or self.adversary not in available_adversaries():
            raise ValueError(
                f"adversary must be one of {available_adversaries()}, got {self.adversary!r}"
            )
        if not isinstance(self.start, str) or self.start not in available_starts():
            raise ValueError(f"start must be one of {available_starts()}, got {self.start!r}")
        if not isinstance(self.scenario, str) or self.scenario not in _SCENARIOS:
            raise ValueError(f"scenario must be one of {_SCENARIOS}, got {self.scenario!r}")
        if not isinstance(self.filtered, bool | np.bool_):
            raise ValueError(f"filtered must be a bool, got {self.filtered!r}")
        for name in ("env_kwargs", "filter_kwargs", "adversary_kwargs", "start_kwargs"):
            value = getattr(self, name)
            if not isinstance(value, Mapping):
                raise ValueError(f"{name} must be a mapping, got {describe(value)}")
            keys = [k for k in value if not isinstance(k, str)]
            if keys:
                raise ValueError(f"{name} keys must be strings, got {keys[0]!r}")
        fixed = {"n_agents", "fov_deg", "max_cycles", "initial_poses"} & set(self.env_kwargs)
        if fixed:
            raise ValueError(
                f"env_kwargs must not set {sorted(fixed)}: the case's own fields and the "
                "sweep's steps/start set them"
            )
        if self.filter_kwargs:
            if not self.filtered:
                raise ValueError(
                    f"filter_kwargs {sorted(self.filter_kwargs)} need filtered=True (they "
                    "configure the safety filter)"
                )
            from fov_marl.wrappers import SafetyFilterWrapper

            valid = keyword_parameters(SafetyFilterWrapper.__init__, skip=2)
            if valid is not None:
                check_keys("filter_kwargs", self.filter_kwargs, valid)
        from fov_marl.config import make_config

        # n_agents and fov_deg (and env_kwargs) validated by the scenario config
        cfg = make_config(
            scenario=self.scenario,
            n_agents=self.n_agents,
            fov_deg=self.fov_deg,
            **dict(self.env_kwargs),
        )
        if self.filtered:  # e.g. a camera range at or below D_s
            from fov_marl.filter_options import check_filter_config

            check_filter_config(cfg, self.filter_kwargs)
        if self.start == "head_on_pair" and self.n_agents < 2:
            raise ValueError(f"start 'head_on_pair' needs n_agents >= 2, got {self.n_agents}")

    @classmethod
    def coerce(cls, case: StressCase | Sequence[Any] | Mapping[str, Any]) -> StressCase:
        """A :class:`StressCase` from itself, a tuple of its fields in order (3 to 10:
        ``adversary``, ``n_agents``, ``fov_deg`` required), or a dict of its fields.

        Raises:
            ValueError: anything else, a dict with an unknown or without a required
                field, a tuple of another length, or an invalid field (naming it).
        """
        names = list(cls.__dataclass_fields__)
        required = names[:3]
        if isinstance(case, StressCase):
            return case
        if isinstance(case, Mapping):
            check_keys("stress case fields", case, names)
            missing = [k for k in required if k not in case]
            if missing:
                raise ValueError(
                    f"a stress case needs the fields {required}, missing {missing} in "
                    f"{describe(case)}"
                )
            return cls(**case)
        if isinstance(case, Sequence) and not isinstance(case, str | bytes):
            if not len(required) <= len(case) <= len(names):
                raise ValueError(
                    f"a stress case tuple holds {len(required)} to {len(names)} fields in "
                    f"the order {names}, got {len(case)}: {describe(case)}"
                )
            return cls(*case)
        raise ValueError(f"a stress case must be a StressCase, tuple or dict, got {describe(case)}")

    def describe(self) -> dict[str, Any]:
        """JSON-friendly dict of the case's fields."""
        d = asdict(self)
        for k in ("env_kwargs", "filter_kwargs", "adversary_kwargs", "start_kwargs"):
            d[k] = dict(d[k])
        return d


# ---------------------------------------------------------------- episodes
def _make_env(case: StressCase, seed: int, steps: int) -> Any:
    from fov_marl.config import make_config
    from fov_marl.envs import fov_coverage_v0, fov_crossing_v0

    module = {"coverage": fov_coverage_v0, "crossing": fov_crossing_v0}[case.scenario]
    kw = dict(case.env_kwargs, n_agents=case.n_agents, fov_deg=case.fov_deg, max_cycles=steps)
    cfg = make_config(scenario=case.scenario, **kw)
    start_rng = np.random.default_rng(np.random.SeedSequence([seed, _START_STREAM]))
    poses = make_start_poses(case.start, cfg, start_rng, **dict(case.start_kwargs))
    env = module.parallel_env(initial_poses=poses, **kw)
    if case.filtered:
        from fov_marl.wrappers import SafetyFilterWrapper

        env = SafetyFilterWrapper(env, **dict(case.filter_kwargs))
    return env


def run_stress_episode(
    case: StressCase, seed: int, steps: int, on_step: Callable[[], None] | None = None
) -> dict[str, Any]:
    """Run one seeded episode of ``case`` for at most ``steps`` steps and measure it.

    Args:
        case: the case (see :class:`StressCase`).
        seed: seeds the env and the filter (an integer >= 0); start poses and adversary
            use child seeds.
        steps: episode length (the env's ``max_cycles``, an integer >= 1); crossing may
            end earlier.
        on_step: called after every step (progress), if given.

    Returns:
        ``{"seed", "steps", "robot_steps", "collisions", "first_collision_step",
        "violation_events", "violation_events_after_start", "violation_robot_steps",
        "min_distance_m", "start_min_distance_m", "encroachment_m", "intervened",
        "action_change_sum", "fallbacks", "statuses", "cause_counts", "chatter_events",
        "filter_chatter_events"}`` (the filter
        entries are None when unfiltered; ``first_collision_step`` None when there was
        none; the three distances None for a one-robot team, which has no pair;
        ``encroachment_m`` is :func:`fov_marl.metrics.pair_encroachment` of the episode).

    Raises:
        ValueError: a bad case, seed, steps or on_step (naming it).
    """
    case = StressCase.coerce(case)
    seed = check_int("seed", seed, 0)
    steps = check_int("steps", steps, 1)
    if on_step is not None and not callable(on_step):
        raise ValueError(f"on_step must be None or a callable, got {describe(on_step)}")
    env = _make_env(case, seed, steps)
    base = env.unwrapped
    adversary = make_adversary(case.adversary, env, **dict(case.adversary_kwargs))
    obs, infos = env.reset(seed=seed)
    adversary.reset(seed=int(np.random.SeedSequence([seed, _POLICY_STREAM]).generate_state(1)[0]))
    d_s = base.config.safety_distance_m
    metrics = metrics_of(next(iter(infos.values())))
    start_events = int(metrics["safety_violations_total"])  # the pairs inside D_s at reset
    n = base.config.n_agents
    d_start = pairwise_distances_batch(base.poses[:, :2])  # (N, N), the start
    np.fill_diagonal(d_start, np.inf)
    d_min = d_start.copy()  # (N, N): each pair's smallest distance so far
    n_steps = robot_steps = viol_rs = intervened = fallbacks = 0
    du_sum = 0.0
    first_collision = None
    statuses: dict[str, int] = {}
    causes = np.zeros(len(SAFETY_CAUSES), dtype=np.int64)
    applied: list[np.ndarray] = []  # (N, 3) per step, NaN for robots no longer live
    nominal: list[np.ndarray] = []  # the policy's own actions, the same layout
    while env.agents:
        actions = adversary.act(obs)
        obs, _, _, _, infos = env.step(actions)
        n_steps += 1
        saf = [safety_of(infos[a]) for a in infos] if case.filtered else []
        step_u = np.full((n, 3), np.nan)
        step_n = np.full((n, 3), np.nan)
        for k, a in enumerate(infos):
            u = saf[k]["applied_action"] if case.filtered else actions[a]
            step_u[base.agent_name_mapping[a]] = np.clip(np.asarray(u, np.float64), -1.0, 1.0)
            u_nom = saf[k]["nominal_action"] if case.filtered else actions[a]
            step_n[base.agent_name_mapping[a]] = np.clip(np.asarray(u_nom, np.float64), -1.0, 1.0)
        applied.append(step_u)
        nominal.append(step_n)
        if on_step is not None:
            on_step()
        robot_steps += len(infos)
        metrics = metrics_of(next(iter(infos.values())))
        if first_collision is None and metrics["collisions_total"] > 0:
            first_collision = n_steps
        if n > 1:
            d = pairwise_distances_batch(base.poses[:, :2])  # as the env's metrics
            np.fill_diagonal(d, np.inf)
            np.minimum(d_min, d, out=d_min)
            live = np.array([base.agent_name_mapping[a] for a in infos], dtype=np.int64)
            viol_rs += int(np.sum(d[live].min(axis=1) < d_s))
        if case.filtered:
            intervened += sum(bool(s["intervened"]) for s in saf)
            fallbacks += sum(bool(s["fallback"]) for s in saf)
            du = np.array(
                [
                    np.asarray(s["applied_action"], np.float64)
                    - np.asarray(s["nominal_action"], np.float64)
                    for s in saf
                ]
            )
            du_sum += float(np.linalg.norm(du, axis=1).sum())
            for s in saf:
                statuses[str(s["status"])] = statuses.get(str(s["status"]), 0) + 1
            causes += cause_counts([s.get("cause_bits", 0) for s in saf])
    env.close()
    flips = chatter_flips(np.asarray(applied).reshape(-1, n, 3))
    own = chatter_flips(np.asarray(nominal).reshape(-1, n, 3))
    return {
        "seed": int(seed),
        "steps": n_steps,
        "robot_steps": robot_steps,
        "collisions": int(metrics["collisions_total"]),
        "first_collision_step": first_collision,
        "violation_events": int(metrics["safety_violations_total"]),
        "violation_events_after_start": int(metrics["safety_violations_total"]) - start_events,
        "violation_robot_steps": viol_rs,
        "min_distance_m": float(metrics["min_distance_episode"]) if n > 1 else None,
        "start_min_distance_m": float(d_start.min()) if n > 1 else None,
        "encroachment_m": pair_encroachment(d_start, d_min, d_s) if n > 1 else None,
        "intervened": intervened if case.filtered else None,
        "action_change_sum": du_sum if case.filtered else None,
        "fallbacks": fallbacks if case.filtered else None,
        "statuses": dict(sorted(statuses.items())) if case.filtered else None,
        "cause_counts": causes.tolist() if case.filtered else None,
        "chatter_events": int(flips.sum()),
        "filter_chatter_events": int((flips & ~own).sum()) if case.filtered else None,
    }


def _job(
    job: tuple[int, StressCase, int, int], on_step: Callable[[], None] | None = None
) -> tuple[int, dict[str, Any]]:
    index, case, seed, steps = job
    return index, run_stress_episode(case, seed, steps, on_step=on_step)


def _aggregate(case: StressCase, eps: list[dict[str, Any]], steps: int) -> dict[str, Any]:
    """One row from the episodes of one case (in seed order)."""
    rs = sum(e["robot_steps"] for e in eps)
    row: dict[str, Any] = {
        "adversary": case.adversary,
        "n_agents": case.n_agents,
        "fov_deg": float(case.fov_deg),
        "start": case.start,
        "filtered": bool(case.filtered),
        "scenario": case.scenario,
        "episodes": len(eps),
        "steps": steps,
        "robot_steps": rs,
        "collisions": sum(e["collisions"] for e in eps),
        "collision_episodes": sum(e["collisions"] > 0 for e in eps),
        "collision_seeds": [e["seed"] for e in eps if e["collisions"] > 0],
        "violation_events": sum(e["violation_events"] for e in eps),
        "violation_events_after_start": sum(e["violation_events_after_start"] for e in eps),
        "violation_robot_steps": sum(e["violation_robot_steps"] for e in eps),
        "min_distance_m": min(
            (e["min_distance_m"] for e in eps if e["min_distance_m"] is not None), default=None
        ),
        "start_min_distance_m": min(
            (e["start_min_distance_m"] for e in eps if e["start_min_distance_m"] is not None),
            default=None,
        ),
        "max_encroachment_m": max(
            (e["encroachment_m"] for e in eps if e["encroachment_m"] is not None), default=None
        ),
        "intervention_rate": None,
        "mean_action_change": None,
        "fallbacks": None,
        "statuses": None,
        "intervention_causes": None,
        "chatter_rate": sum(e["chatter_events"] for e in eps) / max(rs, 1),
        "filter_chatter_rate": None,
    }
    if case.filtered:
        row["intervention_rate"] = sum(e["intervened"] for e in eps) / max(rs, 1)
        du = 0.0
        for e in eps:  # fixed order: the same float sum for any number of workers
            du += e["action_change_sum"]
        row["mean_action_change"] = du / max(rs, 1)
        row["fallbacks"] = sum(e["fallbacks"] for e in eps)
        statuses: dict[str, int] = {}
        for e in eps:
            for k, v in e["statuses"].items():
                statuses[k] = statuses.get(k, 0) + v
        row["statuses"] = dict(sorted(statuses.items()))
        counts = np.sum([e["cause_counts"] for e in eps], axis=0)
        row["intervention_causes"] = {
            c: int(k) / max(rs, 1) for c, k in zip(SAFETY_CAUSES, counts, strict=True)
        }
        row["filter_chatter_rate"] = sum(e["filter_chatter_events"] for e in eps) / max(rs, 1)
    overrides = {
        k: v
        for k, v in case.describe().items()
        if k.endswith("_kwargs") and v  # keep the row small when there are none
    }
    row.update(overrides)
    return row


def run_stress(
    cases: Iterable[StressCase | Sequence[Any] | Mapping[str, Any]],
    episodes: int = 20,
    steps: int = 300,
    seed: int = 0,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    *,
    backend: str = "local",
    ray_address: str | None = None,
    checkpoint: str | os.PathLike | None = None,
) -> list[dict[str, Any]]:
    """Run every case for ``episodes`` seeded episodes of ``steps`` steps.

    Args:
        cases: :class:`StressCase` objects, tuples of their fields in order
            ``(adversary, n_agents, fov_deg, start, filtered, scenario, env_kwargs,
            filter_kwargs, adversary_kwargs, start_kwargs)`` (trailing ones optional)
            or dicts.
        episodes: episodes per case (>= 1); episode k uses seed ``seed + k``.
        steps: steps per episode (>= 1).
        seed: first seed.
        workers: local processes, or the CPUs of a local Ray (:mod:`fov_marl.backends`);
            the rows do not depend on it.
        progress: called as ``progress(done, total)`` in simulated steps: after every
            step when the episodes run in this process, after every episode otherwise
            (an episode that ends early counts its whole budget of ``steps``).
        backend: ``"local"`` or ``"ray"``; the rows do not depend on it.
        ray_address: an existing Ray cluster for ``backend="ray"``.
        checkpoint: a JSON-lines file (module docstring): the episodes already in it
            (same case, seed and steps) are read instead of run, and every episode
            run here is appended as it finishes. Created when missing; a last line cut
            off by a stopped run is dropped. The rows are those of a run without it.

    Returns:
        One dict per case, in the order given (keys in the module docstring, plus the
        case's fields).

    Raises:
        ValueError: a bad case or argument (naming it); a checkpoint that cannot be
            read or written (naming the path), holds a line that is not an episode, or
            was written by other code (:func:`code_id`; naming the file and the line).
    """
    from fov_marl.backends import map_jobs

    if isinstance(cases, StressCase | Mapping | str | bytes) or not isinstance(cases, Iterable):
        raise ValueError(
            "cases must be a list of cases (StressCase objects, tuples or dicts), got "
            f"{describe(cases)}"
            + ("; wrap one case in a list" if isinstance(cases, StressCase | Mapping) else "")
        )
    cases = [StressCase.coerce(c) for c in cases]
    if progress is not None and not callable(progress):
        raise ValueError(
            f"progress must be None or a callable progress(done, total), got {describe(progress)}"
        )
    for name, v in (("episodes", episodes), ("steps", steps), ("workers", workers)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    jobs = [
        (c_idx * episodes + k, case, int(seed) + k, int(steps))
        for c_idx, case in enumerate(cases)
        for k in range(episodes)
    ]
    results: list[dict[str, Any] | None] = [None] * len(jobs)
    sink = None
    if checkpoint is not None:
        keys = [episode_key(case, s_j, n_j) for _, case, s_j, n_j in jobs]  # may raise
        stored, sink = open_checkpoint(checkpoint)
        results = [stored.get(k) for k in keys]
    todo = [j for j in range(len(jobs)) if results[j] is None]
    total = len(jobs) * int(steps)
    state = {"done": (len(jobs) - len(todo)) * int(steps), "this": 0}
    if progress is not None and state["done"]:
        progress(state["done"], total)

    def on_step() -> None:
        state["done"] += 1
        state["this"] += 1
        if progress is not None:
            progress(state["done"], total)

    def on_result(k: int, res: tuple[int, dict[str, Any]]) -> None:
        state["done"] += int(steps) - state["this"]
        state["this"] = 0
        if sink is not None:
            _, case, s_k, n_k = jobs[todo[k]]
            append_episode(sink, case, s_k, n_k, res[1])
        if progress is not None:
            progress(state["done"], total)

    run = [jobs[j] for j in todo]
    # biggest teams first so a pool does not wait on one long tail job
    order = sorted(
        range(len(run)), key=lambda k: (-run[k][1].n_agents * (1 + 3 * run[k][1].filtered), k)
    )
    try:
        out = map_jobs(
            _job,
            run,
            backend=backend,
            workers=int(workers),
            ray_address=ray_address,
            on_result=on_result,
            local_kwargs={"on_step": on_step} if progress is not None else None,
            order=order if (workers > 1 or backend != "local") else None,
        )
    finally:
        if sink is not None:
            sink.close()
    for j, (_, rec) in zip(todo, out, strict=True):
        results[j] = rec
    rows = []
    for c_idx, case in enumerate(cases):
        eps = results[c_idx * episodes : (c_idx + 1) * episodes]
        rows.append(_aggregate(case, eps, int(steps)))
    return rows


# ---------------------------------------------------------------- checkpoints
def stored_rows(
    cases: Iterable[StressCase | Sequence[Any] | Mapping[str, Any]],
    episodes: int,
    steps: int,
    seed: int,
    checkpoint: str | os.PathLike,
    name: str = "checkpoint",
) -> tuple[list[dict[str, Any]], int]:
    """The rows of a sweep from the episodes its checkpoint holds so far, without
    running any: a case's row aggregates its stored episodes (its ``episodes`` entry
    says how many); cases with none are left out. ``run_stress`` with the same
    arguments gives these rows once every episode is stored.

    Args:
        name: how errors name the checkpoint (the CLI's flag).

    Returns:
        ``(rows, number of stored episodes of the sweep)``.

    Raises:
        ValueError: a bad case or a checkpoint that cannot be used (as :func:`run_stress`).
    """
    cases = [StressCase.coerce(c) for c in cases]
    episodes = check_int("episodes", episodes, 1)
    steps = check_int("steps", steps, 1)
    seed = check_int("seed", seed, 0)
    stored = read_checkpoint(checkpoint, name)[0]
    rows, n = [], 0
    for case in cases:
        eps = [
            rec
            for k in range(episodes)
            if (rec := stored.get(episode_key(case, seed + k, steps))) is not None
        ]
        n += len(eps)
        if eps:
            rows.append(_aggregate(case, eps, steps))
    return rows, n


# ---------------------------------------------------------------- the grid
def default_cases(
    full: bool = False, filtered: bool = True, scenario: str = "coverage"
) -> list[StressCase]:
    """The issue-10 acceptance grid or a representative subset of it.

    Args:
        full: ``True``: every adversary × N ∈ :data:`FULL_N_AGENTS` × β ∈
            :data:`FULL_FOV_DEG` × start ∈ :data:`FULL_STARTS`, plus
            :data:`HEAD_ON_PAIR_ADVERSARIES` × N × β from the ``head_on_pair`` start
            (the simplest known failure). ``False``: 13 cases covering every adversary,
            every N, every β and every start at least once.
        filtered: behind :class:`~fov_marl.wrappers.SafetyFilterWrapper` or not.
        scenario: the env every case runs in, ``"coverage"`` (the issue's grid) or
            ``"crossing"`` (the same cases in the crossing env; the adversaries ignore
            its mission, so the cases test the filter in that env's config).

    Raises:
        ValueError: an unknown scenario.
    """
    if not isinstance(scenario, str) or scenario not in _SCENARIOS:
        raise ValueError(f"scenario must be one of {_SCENARIOS}, got {scenario!r}")
    if full:
        grid = [
            StressCase(a, n, b, s, filtered, scenario)
            for a, n, b, s in itertools.product(
                available_adversaries(), FULL_N_AGENTS, FULL_FOV_DEG, FULL_STARTS
            )
        ]
        grid += [
            StressCase(a, n, b, "head_on_pair", filtered, scenario)
            for a, n, b in itertools.product(HEAD_ON_PAIR_ADVERSARIES, FULL_N_AGENTS, FULL_FOV_DEG)
        ]
        return grid
    quick = [
        ("straight", 2, 120.0, "head_on_pair"),
        ("head_on", 2, 45.0, "head_on_pair"),
        ("charge_centre", 4, 120.0, "clustered"),
        ("spin_charge", 4, 45.0, "random"),
        ("chase_last_seen", 8, 90.0, "clustered"),
        ("wait_charge", 4, 360.0, "corner"),
        ("head_on", 8, 120.0, "wall"),
        ("rush", 12, 120.0, "random"),
        ("random", 4, 90.0, "clustered"),
        ("wall_slide", 4, 120.0, "wall"),
        ("straight", 12, 45.0, "corner"),
        ("charge_centre", 24, 120.0, "clustered"),
        ("wait_charge", 8, 360.0, "random"),
    ]
    return [StressCase(a, n, b, s, filtered, scenario) for a, n, b, s in quick]


# ------------------------------------------------------------------- table
#: ``(header, row key)`` of :func:`format_stress_table`.
STRESS_COLUMNS: tuple[tuple[str, str], ...] = (
    ("adversary", "adversary"),
    ("N", "n_agents"),
    ("fov", "fov_deg"),
    ("start", "start"),
    ("filter", "filtered"),
    ("eps", "episodes"),
    ("coll", "collisions"),
    ("coll_eps", "collision_episodes"),
    ("Ds_events", "violation_events"),
    ("Ds_new", "violation_events_after_start"),
    ("Ds_rsteps", "violation_robot_steps"),
    ("min_d_m", "min_distance_m"),
    ("encroach_m", "max_encroachment_m"),
    ("interv", "intervention_rate"),
    ("mean_du", "mean_action_change"),
    ("fallback", "fallbacks"),
    ("top_cause", "intervention_causes"),
    ("chatter", "chatter_rate"),
    ("f_chatter", "filter_chatter_rate"),
)


def format_stress_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Plain-text table of :func:`run_stress` rows (one line per case), then a summary line."""
    from fov_marl.tables import format_cell, format_table

    def cell(key: str, v: Any, row: Mapping[str, Any]) -> Any:
        if key == "filtered":  # "yes", or the particle initialisation when not the default
            init = dict(row.get("filter_kwargs") or {}).get("init", "known")
            return ("yes" if init == "known" else init) if v else "no"
        if key == "fov_deg":
            return f"{v:g}"
        if key == "intervention_causes":  # the most frequent cause and its share
            if not v or not any(v.values()):
                return None
            name = max(v, key=v.get)
            return f"{name} {v[name]:.2f}"
        return v

    body = [[cell(k, r.get(k), r) for _, k in STRESS_COLUMNS] for r in rows]
    table = format_table(body, [h for h, _ in STRESS_COLUMNS])
    bad = sum(1 for r in rows if r.get("collisions", 0) > 0)
    eps = sum(int(r.get("episodes", 0)) for r in rows)
    new = sum(int(r.get("violation_events_after_start") or 0) for r in rows)
    new_cases = sum(1 for r in rows if r.get("violation_events_after_start"))
    enc = max(
        (r["max_encroachment_m"] for r in rows if r.get("max_encroachment_m") is not None),
        default=None,
    )
    tail = (
        f"\nD_s entered after the start: {new} event{'s' * (new != 1)} in {new_cases} "
        f"case{'s' * (new_cases != 1)}"
    )
    if enc is not None:
        tail += f"; closest below what a pair was owed (min(start, D_s)): {format_cell(enc)} m"
    return f"{table}\n\ncases with collisions: {bad} / {len(rows)} ({eps} episodes){tail}"


# --------------------------------------------------------------------- CLI
def _csv(conv: Callable[[str], Any], allowed: Sequence[Any] | None = None):
    """argparse type: a comma-separated list of ``conv`` values (argparse names the flag)."""

    def parse(s: str) -> list[Any]:
        items = [x.strip() for x in s.split(",")]
        if not any(items):
            raise argparse.ArgumentTypeError(f"needs a comma-separated list, got {s!r}")
        if not all(items):
            raise argparse.ArgumentTypeError(f"has an empty item in {s!r}")
        out = []
        for x in items:
            try:
                v = conv(x)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{x!r} is not a valid {conv.__name__}") from None
            if allowed is not None and v not in allowed:
                raise argparse.ArgumentTypeError(
                    f"unknown value {x!r}; choose from {','.join(map(str, allowed))}"
                )
            out.append(v)
        return out

    return parse


def _positive_int(flag: str):
    def conv(s: str) -> int:
        try:
            v = int(s)
        except ValueError:
            v = 0
        if v < 1:
            raise argparse.ArgumentTypeError(f"{flag} must be a positive integer, got {s!r}")
        return v

    return conv


def _non_negative_int(flag: str, hi: int | None = None):
    def conv(s: str) -> int:
        try:
            v = int(s)
        except ValueError:
            v = -1
        if v < 0 or (hi is not None and v > hi):
            allowed = f"in [0, {hi}]" if hi is not None else ">= 0"
            raise argparse.ArgumentTypeError(f"{flag} must be an integer {allowed}, got {s!r}")
        return v

    return conv


#: the largest team ScenarioConfig takes (its n_agents range is [1, 256])
_MAX_AGENTS = 256


def _n_agents(s: str) -> int:
    v = int(s)
    if not 1 <= v <= _MAX_AGENTS:
        raise ValueError(s)
    return v


_n_agents.__name__ = f"team size (integer in [1, {_MAX_AGENTS}])"


def _fov(s: str) -> float:
    v = float(s)
    if not 0.0 < v <= 360.0:
        raise ValueError(s)
    return v


_fov.__name__ = "FoV in (0, 360] degrees"


def add_stress_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``stress`` command to an ``argparse`` subparsers object.

    Sets ``func=cmd_stress`` on it, so ``args.func(args)`` runs the sweep.

    Returns:
        The ``stress`` subparser.
    """
    p = subparsers.add_parser(
        "stress",
        help="adversarial sweep of the safety filter: table of collisions, D_s, interventions",
        description=(
            "Run adversarial policies (fov_marl.adversaries) against SafetyFilterWrapper "
            "and print, per case, collision events, D_s violations (all, and those after the "
            "start: a packed start's pairs are inside D_s from the first step), the minimum "
            "distance, how far any pair came inside what it was owed (min(its start "
            "distance, D_s)), the intervention rate and the mean action change. Without grid "
            "flags: the "
            "quick subset (--quick). --full, or any of --adversaries/--n-agents/--fov-deg/"
            "--starts without --quick: the product of the given lists, the full grid "
            "filling the others. --quick with grid flags filters the quick subset."
        ),
        formatter_class=_help_formatter(),
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="the representative subset")
    mode.add_argument("--full", action="store_true", help="the full acceptance grid")
    p.add_argument(
        "--adversaries",
        type=_csv(str, available_adversaries()),
        default=None,
        help=f"comma-separated, from {','.join(available_adversaries())}",
    )
    p.add_argument(
        "--n-agents",
        type=_csv(_n_agents),
        default=None,
        help=f"team sizes, comma-separated integers in [1, {_MAX_AGENTS}], e.g. 2,4,8",
    )
    p.add_argument("--fov-deg", type=_csv(_fov), default=None, help="degrees, e.g. 45,120")
    p.add_argument(
        "--starts",
        type=_csv(str, available_starts()),
        default=None,
        help=f"comma-separated, from {','.join(available_starts())}",
    )
    p.add_argument(
        "--scenario", choices=_SCENARIOS, default="coverage", help="the env the cases run in"
    )
    p.add_argument(
        "--episodes",
        type=_positive_int("--episodes"),
        default=None,
        help="episodes per case (default: 20 with --full, else 3)",
    )
    p.add_argument(
        "--steps", type=_positive_int("--steps"), default=300, help="steps per episode (dt 0.2 s)"
    )
    p.add_argument(
        "--seed",
        type=_non_negative_int("--seed", MAX_SEED),
        default=0,
        help=f"first seed in [0, {MAX_SEED}]; episode k uses seed + k (default: 0)",
    )
    p.add_argument(
        "--workers",
        type=_positive_int("--workers"),
        default=None,
        help="parallel processes (local) or CPUs of a local Ray (default: 1 local, every CPU "
        "with --backend ray)",
    )
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="where episodes run: local processes, or Ray tasks (the [ray] extra; a local "
        "Ray unless --ray-address); the same rows for the same seeds",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="an existing Ray cluster ('auto' or ray://host:10001) for --backend ray "
        "(default: start a local Ray)",
    )
    p.add_argument(
        "--config",
        metavar="FILE.json",
        default=None,
        help="scenario config fields (a JSON object) for every case, except n_agents, "
        "fov_deg, max_cycles and initial_poses, which the sweep sets (default: none)",
    )
    p.add_argument(
        "--env",
        action="append",
        metavar="FIELD=VALUE",
        help="a scenario config field for every case, repeatable, VALUE parsed as JSON "
        "(e.g. --env safety_distance_m=2.5); overrides --config",
    )
    p.add_argument("--no-filter", action="store_true", help="run the adversaries unfiltered")
    from fov_marl.filter_options import add_filter_arguments

    add_filter_arguments(p, when="unless --no-filter")
    p.add_argument("--json", default=None, metavar="OUT.json", help="also write the rows here")
    p.add_argument(
        "--checkpoint",
        default=None,
        metavar="FILE.jsonl",
        help="append every finished episode to this file and skip the episodes already in "
        "it (same case, seed and steps, written by this fov_marl code): a stopped sweep "
        "resumes with the same rows (default: none)",
    )
    p.add_argument(
        "--fail-on-collision",
        action="store_true",
        help="exit status 1 when any case has a collision event",
    )
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_stress)
    return p


def _help_formatter() -> type:
    """The CLI's help formatter (defaults shown once), plain argparse's standalone."""
    try:
        from fov_marl.cli import _HelpFormatter

        return _HelpFormatter
    except ImportError:  # pragma: no cover
        return argparse.ArgumentDefaultsHelpFormatter


def _env_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """``--config`` / ``--env`` fields applied to every case (checked, naming the flag)."""
    from fov_marl.config import cli_overrides

    file_scenario, kw, sources = cli_overrides(
        getattr(args, "config", None), getattr(args, "env", None)
    )
    if file_scenario is not None and file_scenario != args.scenario:
        raise ValueError(
            f"--config {args.config}: its scenario {file_scenario!r} differs from --scenario "
            f"{args.scenario}; give --scenario {file_scenario}"
        )
    fixed = sorted({"n_agents", "fov_deg", "max_cycles", "initial_poses"} & set(kw))
    if fixed:
        raise ValueError(
            f"{sources[fixed[0]]}: {fixed[0]} is set by the sweep (--n-agents, --fov-deg, "
            "--steps, --starts), not by --config/--env"
        )
    return kw


def _cases_from_args(args: argparse.Namespace) -> list[StressCase]:
    filtered = not args.no_filter
    dims = {
        "adversary": args.adversaries,
        "n_agents": args.n_agents,
        "fov_deg": args.fov_deg,
        "start": args.starts,
    }
    given = {k: v for k, v in dims.items() if v is not None}
    flags = {"adversary": "--adversaries", "n_agents": "--n-agents", "fov_deg": "--fov-deg",
             "start": "--starts"}  # fmt: skip
    for k, v in given.items():
        twice = sorted((x for x, n in collections.Counter(v).items() if n > 1), key=str)
        if twice:  # a repeated value would run (and print) the same cases twice
            raise ValueError(f"{flags[k]} lists {', '.join(map(str, twice))} more than once")
    if args.quick or (not args.full and not given):
        cases = [
            c
            for c in default_cases(full=False, filtered=filtered, scenario=args.scenario)
            if all(getattr(c, k) in v for k, v in given.items())
        ]
        if not cases:
            raise ValueError(
                "no case of the quick subset matches "
                + ", ".join(f"--{k.replace('_', '-')}" for k in given)
                + "; drop --quick to build the grid from the flags"
            )
    else:
        full = {
            "adversary": available_adversaries(),
            "n_agents": list(FULL_N_AGENTS),
            "fov_deg": list(FULL_FOV_DEG),
            "start": list(FULL_STARTS),
        }
        full.update(given)
        cases = [
            StressCase(a, n, b, s, filtered, args.scenario)
            for a, n, b, s in itertools.product(
                full["adversary"], full["n_agents"], full["fov_deg"], full["start"]
            )
        ]
        if args.full and "start" not in given:
            heads = [a for a in HEAD_ON_PAIR_ADVERSARIES if a in full["adversary"]]
            cases += [
                StressCase(a, n, b, "head_on_pair", filtered, args.scenario)
                for a, n, b in itertools.product(heads, full["n_agents"], full["fov_deg"])
                if n >= 2
            ]
    overrides = _env_overrides(args)
    if overrides:
        from fov_marl.config import ConfigError, cli_overrides, source_of_error

        _, _, sources = cli_overrides(getattr(args, "config", None), getattr(args, "env", None))
        try:
            cases = [
                StressCase(**{**c.describe(), "env_kwargs": {**dict(c.env_kwargs), **overrides}})
                for c in cases
            ]
        except ConfigError as exc:
            src = source_of_error(str(exc), sources) or next(iter(sources.values()))
            raise ValueError(f"{src}: {' '.join(str(exc).split())}") from None
    from fov_marl.filter_options import filter_kwargs

    sf = filter_kwargs(
        getattr(args, "filter_tracker", None),
        getattr(args, "filter_controller", None),
        filtered,
        off_hint="drop --no-filter",
        init=getattr(args, "filter_init", None),
    )
    if sf:
        cases = [StressCase(**{**c.describe(), "filter_kwargs": sf}) for c in cases]
    return cases


def cmd_stress(args: argparse.Namespace) -> int:
    """Run the ``fov-marl stress`` command: print the table, optionally write JSON.

    Returns:
        0, or 1 with ``--fail-on-collision`` when some case collided.

    Raises:
        ValueError: a bad combination of flags (naming them) or an invalid case.
    """
    from fov_marl.backends import check_backend, progress_bar

    check_backend(args.backend, args.ray_address)
    for flag, path in (("--json", args.json), ("--checkpoint", args.checkpoint)):
        if path is not None:  # not a folder, not under a file: the shared output check
            check_out_path(flag, path)
    cases = _cases_from_args(args)
    episodes = args.episodes if args.episodes is not None else (20 if args.full else 3)
    resumed = 0
    if args.checkpoint is not None and args.json is not None:
        a, b = (os.path.realpath(x) for x in (args.checkpoint, args.json))
        try:  # a hard link too
            same = a == b or os.path.samefile(a, b)
        except OSError:  # one of them does not exist yet
            same = False
        if same:
            raise ValueError(f"--json and --checkpoint must be different files, both are {a}")
    if args.checkpoint is not None:  # its lines checked before the sweep, naming the flag
        resumed = stored_rows(
            cases, episodes, args.steps, args.seed, args.checkpoint, name="--checkpoint"
        )[1]
        check_writable("--checkpoint", [args.checkpoint])
        if resumed and not args.quiet:
            sys.stderr.write(
                f"{resumed} of {len(cases) * episodes} episodes read from {args.checkpoint}\n"
            )
    if args.json is not None:  # the last check: before the sweep, not after it
        check_writable("--json", [args.json])
    workers = args.workers or ((os.cpu_count() or 1) if args.backend == "ray" else 1)
    t0 = time.perf_counter()
    bar = progress_bar(len(cases) * episodes * args.steps, "stress", "step", not args.quiet)

    def progress(done: int, total: int) -> None:
        bar.update(done - bar.n)

    try:
        rows = run_stress(
            cases,
            episodes=episodes,
            steps=args.steps,
            seed=args.seed,
            workers=workers,
            progress=progress,
            backend=args.backend,
            ray_address=args.ray_address,
            checkpoint=args.checkpoint,
        )
    except KeyboardInterrupt:
        if args.checkpoint is None:
            raise
        bar.close()
        # what is stored so far, so a stopped sweep still shows its table
        rows, n_stored = stored_rows(cases, episodes, args.steps, args.seed, args.checkpoint)
        if rows:
            print(format_stress_table(rows))
            held = f"{n_stored} of {len(cases) * episodes} episodes are in {args.checkpoint} "
            held += "(the rows above hold those)"
        else:
            held = f"no episode of this sweep is in {args.checkpoint} yet"
        sys.stderr.write(f"stopped: {held}; the same command resumes\n")
        raise
    finally:
        bar.close()
    print(format_stress_table(rows))
    if args.json:
        path = Path(args.json)
        if path.parent and not path.parent.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
        settings = {k: v for k, v in vars(args).items() if k not in ("func",) and not callable(v)}
        out = {
            "settings": {**settings, "episodes": episodes},
            # wall_s is this run's: the episodes read from --checkpoint ran earlier
            "wall_s": time.perf_counter() - t0,
            "episodes_from_checkpoint": resumed,
            "rows": rows,
        }
        write_json(path, out, indent=2)
        if not args.quiet:
            print(f"\nwrote {path}")
    collided = any(r["collisions"] > 0 for r in rows)
    return 1 if (args.fail_on_collision and collided) else 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m fov_marl.stress [flags]``: the ``stress`` command on its own."""
    parser = argparse.ArgumentParser(prog="fov_marl.stress")
    sub = parser.add_subparsers(dest="command")
    add_stress_parser(sub)
    args = parser.parse_args(["stress", *(sys.argv[1:] if argv is None else argv)])
    try:
        return args.func(args)
    except KeyboardInterrupt:
        if os.environ.get("FOV_MARL_DEBUG"):
            raise
        sys.stderr.write("fov_marl.stress: interrupted\n")
        return 130
    except ValueError as exc:
        if os.environ.get("FOV_MARL_DEBUG"):
            raise
        sys.stderr.write(f"fov_marl.stress: error: {exc}\n")
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
