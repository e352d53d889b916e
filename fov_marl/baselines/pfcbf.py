"""Scripted policies built on :class:`fov_marl.pipeline.PfCbfPipeline`.

======================  ==========================================================
name                    what
======================  ==========================================================
``pfcbf``               the paper: particle filters + Lloyd u* + FoV CBFs + HQP
``lloyd-pf``            ablation: Lloyd on the particle-filter estimates, no CBF
``ideal``               the paper's comparison: true neighbour positions (isotropic
                        sensing, ideal communication), same CBF safety row, no FoV rows
======================  ==========================================================

All are decentralised except ``ideal`` (by definition). The particle filters start
from the true start poses (the paper's assumption, VII-B: "every robot knows the
starting position of each one of its neighbors"): the policy reads ``env.poses`` once,
on the first :meth:`act` after :meth:`reset`; pass ``init="uniform"`` to drop it.
Deterministic under ``reset(seed)``.

Safety of ``pfcbf`` as measured on commit 336ce19 (budget per bearing with the glance,
no keep-right in coverage: :data:`PFCBF_COVERAGE_DEFAULTS`; 40 m arena, β = 120°, 1000
steps; ``tests/test_safety_acceptance.py``, slow; crossing, unchanged, on be3bc83: 4
robots, 20 seeds):

=========================  ==========  ==============  ==================  ===========
team                       seeds       collision ev.   D_s violations      min dist.
=========================  ==========  ==============  ==================  ===========
N = 6                      0-19        0               0                   2.63 m
N = 12                     0-19        0               0                   2.39 m
N = 24                     0-19        0               0                   2.06 m
N = 48                     0-4         0               0                   2.22 m
N = 100, L = 40·√(N/6)     0-2         0               0                   2.60 m
N = 200, L = 40·√(N/6)     0-2         0               0                   2.64 m
crossing, 4 robots         0-19        0 (all arrive)  0                   2.43 m
=========================  ==========  ==============  ==================  ===========

Re-run on 161a8a0 (this release's controller; ``pytest -m slow`` on the four pfcbf
acceptance tests of ``tests/test_safety_acceptance.py``, 8 cases, 4,405 s on one core):
all pass, so every row above still has 0 collision events (the crossing row also 0 D_s
events, all arrive) and every N = 6 seed settles within 0.5% of ``ideal``'s final η; the
minimum distances of the table were not re-measured.

N = 6: team speed over the last 50 s at most 0.005 m/s, final η 0.9945-0.9967. On the
single-vector budget of be3bc83 N = 100 seed 0 had one D_s violation (steps 501-522,
min 1.74 m): a robot sliding sideways, outside its camera sector, 0.21 m in 21 steps
towards a neighbour it did not see and that saw it but stood still, within the 1 m
budget, which bounds such drift to stay clear of contact (2 r = 1 m), not of D_s.
Before the local re-seed of a deleted belief (:class:`fov_marl.estimation.TrackerParams`
``recovery_reseed``; commit a664dd3) N = 24 seed 12 collided (min 0.54 m): a robot that
turns fast lets its belief of a neighbour it has just seen lag the turn, the particles
fall inside the view while the neighbour has just left it, are all deleted (Eq. 4), and
the block was re-seeded uniform over the arena, so the robot drove along the edge of its
view into the neighbour just outside it. Re-seeded outside the view around the deleted
cloud, the seed keeps 2.36 m.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fov_marl.baselines.registry import register_policy
from fov_marl.control import ControllerParams
from fov_marl.envs.rendering import draw_beliefs
from fov_marl.estimation import TrackerParams
from fov_marl.pipeline import PfCbfPipeline
from fov_marl.validation import check_bool, check_params, check_seed, fov_parallel_base

__all__ = ["PipelinePolicy", "PFCBF_COVERAGE_DEFAULTS"]

#: Controller settings of the PF+CBF policies in the coverage scenario that differ from
#: :class:`ControllerParams`'s defaults (dict overrides are applied on top): the blind
#: travel budget (:mod:`fov_marl.control.safety` Section 2d). Measured, pfcbf in the 40 m
#: arena, N = 48: without it 2 collision events in seeds 0-3 (seed 3: min 0.03 m, a robot
#: sliding blind into a neighbour it had never seen); with it seeds 0-4 have none (min
#: 2.13 m), nor N = 12 seeds 0-9 or N = 24 seeds 0-5, and at N = 6 (seeds 0-3) η stays
#: within 0.3% of ``ideal``.
#: Not in the crossing scenario: there it stalled robots that slide sideways to their
#: targets while the FoV levels keep their neighbours in view (1-3 of 4 arrivals).
#: The budget's leak is 120 s (``blind_travel_memory_s``; :class:`ControllerParams`: 30 s):
#: with 30 s a robot creeping blind at 0.03 m/s never fills the 1 m budget (0.03 x 30 =
#: 0.9 m in steady state). Measured (N = 48, seed 4, with the tracker's bias test on): with
#: 30 s a robot crept blind into a neighbour whose belief it held 24 m off (1 collision
#: event, min 0.60 m); with 120 s (creep above 0.0083 m/s blocked) min 2.32 m, and with no
#: leak 2.42 m, but no leak cost coverage at N = 6 (seed 0: final η 0.9886 against 0.9945)
#: while 120 s keeps it (seeds 0-3: 0.9943 / 0.9959 / 0.9942 / 0.9948 against 0.9945 /
#: 0.9959 / 0.9938 with 30 s).
#:
#: The budget is kept per bearing (``blind_travel_bearings = 24``, safety Section 2e) and
#: the look before the leap outranks the FoV levels for its step (``look_yields_fov``),
#: as in the safety filter; "keep right" (``deadlock_turn_deg``) is off. The single
#: vector this policy had before forgot the travel of a robot sliding at 0.6 m/s 49° off
#: its heading (inside the view less its 10° margin) while a neighbour it never saw lay
#: 33-56° beside that direction: with keep-right off, N = 200 (L = 230.9 m) seed 0 had
#: two such robots close from 2.86 m to 0.994 m in 37 steps. Keep-right, meant for the
#: crossing deadlock of VII-D, stranded coverage robots: blocked by the rows of
#: neighbours they did not see, it turned u* by 60° and drove them round them, 20 m to
#: the wall (behind the safety filter, seeds 5 and 6: final η 0.9816 / 0.9831). Measured
#: (N = 6, β = 120°, seeds 0-19, 1000 steps; before / after): alone, final η 0.9955 /
#: 0.9957, time to the normalised threshold 7.21 / 7.55 s (median 6.6 / 7.0), largest
#: team speed over the last 50 s 0.021 / 0.005 m/s, 0 collisions (min 2.551 / 2.629 m);
#: behind the safety filter 0.9937 (min 0.9816) / 0.9957 (min 0.9944), 13.0 / 13.5 s,
#: robot-steps changed 53% / 41%, largest speed over the last 50 s 0.062 / 0.007 m/s.
#: N = 200 in the scaled arena, seeds 0-2: min distance 2.641 m, no D_s event (before:
#: 2.36 m). Per bearing without the glance, by contrast, stopped robots that drive
#: straight (N = 6: seeds 6 and 9 never settled), since the FoV levels forbade the
#: sideways look that releases a bearing.
#: Since the arc guard stops a creep to keep a turn (``arc_guard_stop``, a
#: :class:`ControllerParams` default; safety Section 1c), the same seeds give alone
#: 0.9956, 7.12 s, 0.003 m/s, min 2.665 m; behind the filter 0.9952 (min 0.9927), 9.63 s,
#: 40% changed, 0.014 m/s. At β = 45° seed 7 the guard had frozen the whole team (η 0.06
#: after 60 s, 0.96 with the stop).
PFCBF_COVERAGE_DEFAULTS: dict[str, Any] = {
    "blind_travel_m": 1.0,
    "blind_travel_memory_s": 120.0,
    "blind_travel_bearings": 24,
    "look_yields_fov": True,
    "deadlock_turn_deg": 0.0,
}


class PipelinePolicy:
    """A team policy driving :class:`PfCbfPipeline` (see the module docstring).

    Args:
        env: a fov_marl ParallelEnv (or wrapper); its config and, for the known
            initialisation / oracle, its ground-truth ``poses`` are read.
        use_cbf, estimates, init: see :class:`PfCbfPipeline`.
        tracker_params, controller_params: dataclasses (used as given) or dicts of
            overrides (in coverage, on top of :data:`PFCBF_COVERAGE_DEFAULTS`).
        controller: ``"auto"``, ``"batched"`` or ``"loop"`` (see :class:`PfCbfPipeline`;
            one team: ``"auto"`` is the per-robot loop, measured as fast as the batched
            controller at N = 6-24 and bit-identical to the numbers of before).
        adopt_applied: behind a :class:`~fov_marl.wrappers.SafetyFilterWrapper`, move the
            particles and book the blind travel by the actions the filter applied, not
            by the policy's own (:meth:`_adopt_applied`); False (an ablation) keeps the
            policy's own, as before this option. No effect without a filter.

    Raises:
        ValueError: an env that is not a fov_marl ParallelEnv or a wrapper keeping its
            observations (a vector env, an AEC env, ``BeliefObservationWrapper``), a
            ``tracker_params`` / ``controller_params`` dict with a field the dataclass
            does not have, or a non-bool ``adopt_applied`` (and the pipeline's own
            checks of ``estimates``, ``init`` and ``controller``).
    """

    def __init__(
        self,
        env: Any,
        *,
        use_cbf: bool = True,
        estimates: str = "tracker",
        init: str = "known",
        tracker_params: TrackerParams | dict | None = None,
        controller_params: ControllerParams | dict | None = None,
        controller: str = "auto",
        adopt_applied: bool = True,
    ) -> None:
        self.base = fov_parallel_base(
            "a team policy", env, "a policy acts in one env; run one per copy"
        )
        self.env = env
        self.adopt_applied = check_bool("adopt_applied", adopt_applied)
        cfg = self.base.config
        tracker_params = check_params("tracker_params", tracker_params, TrackerParams)
        defaults = (
            PFCBF_COVERAGE_DEFAULTS
            if use_cbf and estimates == "tracker" and cfg.scenario == "coverage"
            else None
        )
        controller_params = check_params(
            "controller_params", controller_params, ControllerParams, defaults
        )
        self.pipeline = PfCbfPipeline(
            cfg,
            tracker_params=tracker_params,
            controller_params=controller_params,
            use_cbf=use_cbf,
            estimates=estimates,  # type: ignore[arg-type]
            init=init,  # type: ignore[arg-type]
            controller=controller,  # type: ignore[arg-type]
        )
        self.agents = list(self.base.possible_agents)
        self._seed: int | None = None
        self._started = False
        self._sent: np.ndarray | None = None  # (N, 3) the last filter() output
        self._sent_rows: np.ndarray | None = None  # (N,) its rows returned as actions

    @property
    def last_timings(self) -> dict[str, float]:
        """Team wall-clock seconds of the last :meth:`act`, per stage."""
        return self.pipeline.last_timings

    def reset(self, seed: int | None = None) -> None:
        self._seed = check_seed("seed", seed)
        self._started = False
        self._sent = self._sent_rows = None

    def act(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        pl = self.pipeline
        oracle = pl.estimates == "oracle"
        if not self._started:
            pl.reset(obs, seed=self._seed, initial_poses_world=self.base.poses)
            self._started = True
        else:
            self._adopt_applied()
            pl.observe(obs, poses_world=self.base.poses if oracle else None)
        act = pl.filter(pl.desired_inputs())
        self._sent = np.array(act, dtype=np.float32)
        self._sent_rows = np.array([a in obs for a in self.agents])
        return {a: act[i] for i, a in enumerate(self.agents) if self._sent_rows[i]}

    def _adopt_applied(self) -> None:
        """Behind a :class:`~fov_marl.wrappers.SafetyFilterWrapper` (``env`` is or wraps
        one), take the actions it applied at the last step as this pipeline's own applied
        actions (:meth:`~fov_marl.pipeline.PfCbfPipeline.set_applied`): each robot's
        particle filters then move by its real motion, and its blind travel budget books
        the travel it made, not the travel it asked for. Only when the filter's nominal
        actions are exactly those this policy returned (the filter was fed by it)."""
        last = getattr(self.env, "last_actions", None) if self.adopt_applied else None
        if last is None or self._sent is None or self._sent_rows is None:
            return
        rows = self._sent_rows
        nominal = np.asarray(last.nominal, dtype=np.float32)
        if nominal.shape != self._sent.shape or not np.array_equal(
            nominal[rows], np.clip(self._sent[rows], -1.0, 1.0)
        ):
            return
        applied = self._sent.copy()
        applied[rows] = np.asarray(last.applied, dtype=np.float32)[rows]
        self.pipeline.set_applied(applied)

    def draw(self, canvas: Any) -> None:
        """Render layer: robot 0's particles and ellipses (``env.add_render_layer``)."""
        if self._started:
            draw_beliefs(canvas, self.pipeline, robots=(0,))


#: what make_policy("pfcbf" / "lloyd-pf" / "ideal", env, **options) accepts: the
#: PipelinePolicy keywords the factories leave free
_PIPELINE_OPTIONS = ("init", "tracker_params", "controller_params", "controller", "adopt_applied")


@register_policy("pfcbf", options=_PIPELINE_OPTIONS)
def _make_pfcbf(env: Any, **kw: Any) -> PipelinePolicy:
    return PipelinePolicy(env, use_cbf=True, estimates="tracker", **kw)


@register_policy("lloyd-pf", options=_PIPELINE_OPTIONS)
def _make_lloyd_pf(env: Any, **kw: Any) -> PipelinePolicy:
    return PipelinePolicy(env, use_cbf=False, estimates="tracker", **kw)


@register_policy("ideal", options=_PIPELINE_OPTIONS)
def _make_ideal(env: Any, **kw: Any) -> PipelinePolicy:
    return PipelinePolicy(env, use_cbf=True, estimates="oracle", **kw)
