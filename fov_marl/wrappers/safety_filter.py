"""SafetyFilterWrapper: any policy's actions made safe by the paper's PF + FoV-CBF QP.

The incoming action of robot i is read as its desired input u* (mapped to a body
velocity exactly as the env maps actions, :func:`fov_marl.spaces.action_to_velocity`)
and replaced by the output of robot i's FoV-CBF controller (Eq. 12, 16-19), whose
neighbour estimates come from robot i's own particle filters fed only with robot i's
observations and the actions actually applied. It is the same pipeline as the
``pfcbf`` baseline (:class:`fov_marl.pipeline.PfCbfPipeline`), with u* from the
policy instead of Lloyd.

Spaces, agents, rewards, terminations and truncations are those of the wrapped env.
``infos[agent]`` gains flat ``safety/*`` entries (:mod:`fov_marl.infos`; present at
``reset()`` too, with neutral values), per robot and step:

==========================  =======================================================
key                         meaning
==========================  =======================================================
``safety/nominal_action``   (3,) float32, the policy's action (clipped to [-1, 1])
``safety/applied_action``   (3,) float32, the action sent to the env
``safety/intervened``       bool, ‖u − proj(u*)‖ above the controller's tolerance, proj
                            mapping u* into the controller's speed polygon (16 sides
                            inside ‖v‖ ≤ v_max): ``[1, 0, 0]`` is applied as
                            ``[0.981, 0, 0]``, status ``"unconstrained"``, not intervened
``safety/status_code``      int, QP outcome (:data:`fov_marl.infos.SAFETY_STATUSES`:
                            ``"reset"`` (0, at ``reset()``), ``"unconstrained"``,
                            ``"solved"``, ``"relaxed"``, ``"safety_fallback"``,
                            ``"degraded"``, ``"qp_failed"``, ``"invalid_input"``,
                            ``"no_neighbours"`` (a one-robot team without wall rows);
                            see :class:`~fov_marl.control.ControlResult`)
``safety/fallback``         bool, a fallback input was used (``"safety_fallback"``: the
                            collision rows could not all be met)
``safety/cause_bits``       int, why the action was changed: bit k for
                            :data:`fov_marl.infos.SAFETY_CAUSES` ``[k]`` (the kinds of
                            collision row u* breaks, the FoV levels, the look, a
                            fallback); 0 when it was not
==========================  =======================================================

:func:`fov_marl.infos.safety_of` returns them as a dict with the ``status`` string and
the ``causes`` names.

Wall-clock cost is kept out of ``infos`` (so equal seeds give equal infos): the
attribute ``last_cpu_s`` holds the seconds the filter spent on the whole team in the
last step (tracker + QPs). The attribute ``last_actions`` holds the last step's
``(nominal, applied)`` action arrays (:class:`FilteredActions`): a policy that models
its own motion reads there what its robots really did. The ``pfcbf`` policy does
(``adopt_applied``): it moves its own particle filters by the applied actions and
books them in its blind travel budget. Before it did, pfcbf behind the filter moved its
particles by the actions it had asked for, and lost track of the neighbours it did not
see (truth inside its 95% ellipses: 0.46 against 0.99, N = 6, β = 120°, seed 0, 150
steps; ``tests/baselines/test_policies.py``).

The wrapped policy is unknown, so the neighbours' motion model is the mode mixture
(``"mixture"``: static random walk, Eq. 20, Eq. 22 and constant velocity, with mode
probabilities learnt from detections; :mod:`fov_marl.estimation`), calibrated for
pfcbf, random and adversarial neighbours. Measured on the adversarial quick sweep
(``fov-marl stress --quick``, 13 cases x 3 episodes): with the single ``"static"``
model robots packed against a wall collided (2 cases), with the mixture none did;
the mixture's wider clouds cost interventions (random actions, N = 6, 120°: 38% of
robot-steps changed against 27%). The paper's Eq. 20/22 models are selected with
``tracker_params={"motion_model": "coverage"}`` / ``"crossing"``.

What makes the actions safe (details and measurements in
:mod:`fov_marl.control.safety`): every robot's collision rows are built on the
*uncertainty* of its estimates, not their means (a chance-constrained separating
line per neighbour; speed bounds towards the particles of neighbours it does not
see; the arena walls), hold in discrete time at the env's dt, and share each pair's
closing budget between the two robots, which both run the filter. They form the top
level of the hierarchy (Eq. 18), above the FoV levels; when they cannot all be met
the documented safe fallback is used (``status == "safety_fallback"``). The FoV
levels turn the camera (they never translate the robot), so the filter changes a
policy's translation only near a neighbour, seen or believed, or a wall (beyond the
speed polygon's shrink of at most 1.9%, see ``safety/intervened``). Measured on
harmless random actions (N = 6, β = 120°; numbers of the filter as shipped), the
share of robot-steps it changes grows with the time a policy ignores its neighbours:
51-54% over the first 150 steps, 70% over 300 steps (43% and 67% with the earlier
1 m blind travel budget, below) and 0.84-0.88 over 1000 steps (5 episodes, mean 0.854;
0.845 with 1 m; ``tests/test_safety_acceptance.py``, slow). The first version's blanket
motion cone changed 96%. It grows because the beliefs of unseen neighbours spread to
the prior: the median std reaches 12 m by step 500, and the neighbours are seen in
3-10% of the steps. The blind rows bound the speed towards the *nearest* particle (a
quantile of a diffuse belief let a chasing adversary drive blind into a neighbour), so
a policy that never looks moves blind only slowly. With β = 360° (no blind
directions) the share is 0.32-0.41 over 1000 steps, mostly from the half-planes of
neighbours beyond R_d. Their Gaussian fit (Section V) reaches within a few metres of
the robot, although the camera shows that nobody is within R_d. The issue's goal of
30% is not met.

Where the changes come from (random actions, N = 6, β = 120°, seeds 0-1 x 300 steps;
a changed robot-step counts for every kind of row its u* violated): the blind rows
30-41% of the robot-steps, the lines of undetected neighbours 21-27%, the blind travel
budget 22-24%, the FoV levels alone 8-10%, detected neighbours and walls 0-3%. The
kinds overlap: with the blind rows all but gone (``blind_risk`` 0.02: 0-0.6%) 67-73%
are still changed, the travel budget and the FoV levels taking over, so no single
knob reaches the goal. ``undetected_quantile="particles"`` (the particles' own
quantile instead of the Gaussian's for those lines) changes 17% and 15% at β = 360°
(18% and 34% with the Gaussian) and 78% against 81% at 120° (5 x 500 steps); it is an
ablation, not stress-swept. Every step reports its own causes (``safety/cause_bits``):
on the shipped filter (random actions, seeds 0-1 x 150 steps, 60.8% changed) the blind
travel budget 33.6% of the robot-steps, the look turn 19.8%, the blind rows 17.1%, the
lines of neighbours 13.4%, the FoV levels alone 9.3%, the last-seen and density rows
3% (CHANGELOG, with pfcbf, ``ideal`` and the learned policy).

The controller defaults are :class:`~fov_marl.control.ControllerParams`' except
:data:`FILTER_CONTROLLER_DEFAULTS`: no "keep right" deadlock steering, which would
add a behaviour of the filter's own to the policy's; rows on the camera's own report
of each seen neighbour (``detection_rows``, :mod:`fov_marl.control.safety` Section 1d:
a robot never closes on where its camera sees a neighbour faster than the raw
detection's chance constraint allows, whatever its tracker believes; red team 9 had a
posterior drift through the robot and its row steer the robot into the neighbour it
saw); last-seen points released only when their whole uncertainty disk is in view
(``last_seen_release="disk"``, safety Section 2c: a point 0.75 m off the truth was
"seen empty" while its neighbour stood outside a 45° view); and the blind travel budget
(``blind_travel_m = 0.5`` m, per bearing, no leak, the glance outranking the FoV levels;
:mod:`fov_marl.control.safety` Sections 2d-2e, :func:`filter_controller_defaults`):
an arbitrary
policy may drive persistently into space its robot has not looked at (``pfcbf`` uses
1 m in coverage, and none in crossing, where it stopped robots that keep their
neighbours in view while sliding sideways to their targets; measured, 4 crossing
seeds: 1-3 of 4 arrivals with it, 4 of 4 in 33 s without). The filter's budget was
1 m until a wider stress grid (N = 2 and 24, β = 45° and 90°, 144 cases x 2 episodes)
found a collision. It was ``wait_charge``, N = 24, β = 45°, ``head_on_pair`` start,
seed 300. A robot drove at 0.9 m/s along the edge of its 45° view, 18-25° off its
heading, towards a neighbour parked 2.5 m away just outside that view. The robot had
not seen that neighbour for 44 s: its belief was 8 m away with a std of 8 m, and no
particle lay near. It spent the whole 1 m budget in 1.2 s and touched at 0.95 m.
With 0.5 m the episode kept 2.44 m, until the arc guard (safety Section 1c) sent it on
another course on which a robot drove forward, in view, towards a neighbour parked
2.08 m away at −34° to −38°: every forward step zeroed the budget along its way, and it
closed to 1.41 m. The budget is therefore kept per bearing (``blind_travel_bearings =
24``, safety Section 2e): no bearing the robot has not had in view is approached by
more than 0.5 m; the episode keeps 2.54 m. In the previous release it stayed the single
vector for views of 97.2° and wider, where a *static* point outside the view is passed far
enough, until the slow adversarial test (N = 8, 120°, robots that drive at their
nearest teammate) had two robots that never saw each other, each travelling where it
looked, close from 1.87 m to contact; it is now per bearing at every β, without the
30 s leak that let a slow creep through (measurements in
:func:`filter_controller_defaults`). Random actions (N = 6, 120°, 2 x 150 steps) are
changed in 72% of the robot-steps against 50% with the vector, the glance's turns
included. Both episodes are regression tests. The look before the leap (the turn that
releases a bearing's budget by looking at it) comes early, at ¾ B, only for a u* that
keeps its course (``look_persistence_deg = 45``: its translation's bearing in Σ_w within
45° of the last step's); any other u* looks once the bearing is spent. A purposeful
policy still glances before it is stopped; a command that changes course every step is
not turned round for travel it will not continue. Measured (N = 6, 120°): random actions
(2 x 150 steps) changed in 60.9% of robot-steps against 68.8% with every look early (5 x
1000 steps: 0.886 against 0.895); pfcbf behind the filter (seeds 0-19) final η 0.9954,
9.49 s to the normalised threshold, 37.1% changed (every look early: 0.9954, 9.64 s,
37.7%); the shipped learned policy 0.9964, 15.7 s, 81.3% (0.9957, 15.5 s, 83.3%). Not
kept: every look at the spent budget (``look_fraction = 1``: random 56.9%, but pfcbf
18.5 s to the threshold) and 20° (random 58.6%, the learned policy 19.8 s).
An option, off by default, clears the
budget while no neighbour can be near (``controller_params={"blind_travel_reach":
True}``, safety Section 2f): every neighbour lies in the disk it can have reached at
``v_max`` since its last detection (the env's noise is truncated, so the disk is sure),
and while every such disk is farther than ``D_s + 2 B + 2 v_max dt`` nobody can be
within that distance in any direction, more than a look shows. Measured, on against
off: random actions (N = 6, 120°, 2 x 150 steps) changed in 58.8% of the robot-steps
against 68.8% (50.4% against 60.9% with the steady-course look) (5 x 1000 steps: 0.879
against 0.895); pfcbf behind the filter (N = 6,
120°, seeds 0-19, 1000 steps) final η 0.9955 against 0.9954, 8.07 s to the normalised
threshold against 9.64 s, 36.4% changed against 37.7%, but 28.7 s to η = 0.99 against
22.9 s; narrow views below (:func:`filter_controller_defaults`); the stress sweeps
swept it clean (CHANGELOG). It is not the default because the shipped learned policy,
trained behind the filter without it, loses its lead over pfcbf behind it (final η
0.0020 below pfcbf's on average over seeds 0-19, against above without it; 17.1 s to
the threshold against 15.5 s).
There is also no yielding of lost neighbours' FoV levels (``lost_fov_yield``, pfcbf's
liveness rule for crossing): behind the filter those levels are what keeps a policy
that never looks turning towards its neighbours. Measured with the learned policy
(seeds 0-4) and the stress grid: with the yield, final η fell from 0.92-0.99 to
0.47-0.99, and together with ``lost_sigma_max_m = 2`` m (no half-plane for diffuse
undetected beliefs; it cut the random-action change rate from 68% to 53%) the
``wait_charge`` adversary (N = 12, β = 120°, random start, seed 101) collided. Both
stay off here; that episode is a regression test.

Where it holds. The filter refuses an env whose camera cannot see to D_s
(``detection_range_m <= safety_distance_m``, a ``ValueError``): a neighbour first
seen inside D_s cannot be kept out of it, and a 1 m range (2 r) collided (red team
9, :func:`filter_controller_params`). The stress sweeps behind the safety claim use
the default 2000 particles; with 500 (``tracker_params={"n_particles_total": 500}``,
3x faster) the default env swept clean, but robots started inside D_s (packed starts)
collided in envs with 0.71 m detection noise, a 4 m camera, ``v_max_mps = 2`` or
``dt_s = 0.4`` (none of them at 2000 particles). The rows on the camera's report and
the disk release of last-seen points keep all five clear (their sweeps rerun, 648
episodes, 0 collisions; CHANGELOG). With all four changes at once (0.8 m a step, 0.71 m
noise) two robots packed 1.1 m apart collided at 2000 particles too, in 4 of 18
episodes of a 324-episode sweep: one robot had seen its neighbour 1.165 m behind its
shoulder, turned away, and 96 s later backed blind into it on the bearing's unspent
0.5 m budget, which bounds a pair's closing by 2 B and so keeps out of contact only
robots that start at least D_s apart. A bearing the camera saw a neighbour at inside
D_s therefore starts spent by what the pair has already closed
(``blind_travel_prespend``, safety Section 2g); the sweep reruns clean. The other
mechanism there, a report outside the camera sector, is mended only by the option
``detection_sector`` (Section 1e), off: it costs the learned policy behind the filter
(CHANGELOG).

The particle filters start from the true start poses (the paper's assumption,
VII-B) read from ``env.unwrapped.poses`` at reset; pass ``init="uniform"`` to avoid
it. Filter randomness is seeded from the ``seed`` given to :meth:`reset` (child
streams of ``SeedSequence(seed)``, independent of the env's own stream).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

from fov_marl.control import ControllerParams
from fov_marl.envs.base import FORWARDED_MAX_CYCLES
from fov_marl.envs.rendering import draw_beliefs
from fov_marl.estimation import TrackerParams
from fov_marl.infos import reset_safety_infos, set_safety_infos
from fov_marl.pipeline import PfCbfPipeline
from fov_marl.spaces import action_to_velocity
from fov_marl.validation import ConfigError, check_int, check_params, fov_parallel_base


class FilteredActions(NamedTuple):
    """One step of :class:`SafetyFilterWrapper`: ``nominal`` (the policy's actions,
    clipped to ``[-1, 1]``) and ``applied`` (what the filter sent to the env), each
    ``(N, 3)`` float32 normalised actions by robot index."""

    nominal: np.ndarray
    applied: np.ndarray


__all__ = [
    "SafetyFilterWrapper",
    "FilteredActions",
    "FILTER_CONTROLLER_DEFAULTS",
    "FILTER_TRACKER_DEFAULTS",
    "filter_controller_defaults",
    "filter_controller_params",
    "vector_view_margin_deg",
]

#: Controller settings of the filter that differ from :class:`ControllerParams`'s
#: defaults (module docstring); ``controller_params`` dicts are applied on top
#: (:func:`filter_controller_defaults`).
FILTER_CONTROLLER_DEFAULTS: dict[str, Any] = {
    "deadlock_turn_deg": 0.0,
    "detection_rows": True,
    "last_seen_release": "disk",
    "blind_travel_m": 0.5,
    "blind_travel_bearings": 24,
    "blind_travel_memory_s": math.inf,
    "blind_travel_prespend": True,
    "look_yields_fov": True,
    "look_persistence_deg": 45.0,
    "lost_fov_yield": False,
}
#: Tracker settings of the filter that differ from :class:`TrackerParams`'s defaults: the
#: mixture (also ``"auto"``'s), and the bias test (``recovery_bias_alpha``, tracker step
#: 4): on in the filter, where a robot that saw its neighbour broke D_s without it (the
#: stress grid's seed 9100: 1.977 m, 2.485 m with it; the whole grid rerun on it: 0
#: collisions, 0 D_s events from non-packed starts). Off in ``TrackerParams`` (and so
#: in pfcbf): turned on there it sent pfcbf, N = 48, seed 4, on a course where a robot
#: crept blind at 0.03 m/s into a neighbour whose belief was 24 m off (2 collision
#: events; 0 with it off, min 1.38 m), a weakness of pfcbf's 1 m blind budget that the
#: test only exposes. And the fused recovery of collapsed clouds (``ess_recovery="fuse"``,
#: tracker step 4): the full stress grid (760 cases, seed 17000) had one collision,
#: ``straight``, N = 12, β = 360°, wall start: a detection 1.2 m off (3.8 σ of Σ_MEAS)
#: re-seeded the narrow cloud of a neighbour 1.1 m away from N(z, Σ_MEAS) alone, beyond
#: the wall, and the clamp put it on the robot itself (0.997 m); fused, the pair keeps
#: its 1.1 m. Calibration with it (tests/estimation/test_mixture_calibration.py): 0.938 to
#: 0.975 for the eight behaviours, against 0.957-0.972 with the re-seed. pfcbf keeps
#: the re-seed (``TrackerParams``' default): its slow suite was not rerun on it.
FILTER_TRACKER_DEFAULTS: dict[str, Any] = {
    "motion_model": "mixture",
    "recovery_bias_alpha": 0.2,
    "ess_recovery": "fuse",
}


def filter_controller_defaults(config: Any, overrides: Any = None) -> dict[str, Any]:
    """:data:`FILTER_CONTROLLER_DEFAULTS` for the env of ``config`` (a
    :class:`~fov_marl.config.ScenarioConfig`) and the ``overrides`` the user gives (a
    dict, a :class:`ControllerParams`, used as given, or None): the blind travel budget is
    kept per bearing (``blind_travel_bearings = 24``, safety Section 2e), without a leak
    (``blind_travel_memory_s = inf``), and the FoV levels yield to the glance that resets
    it (``look_yields_fov``). Where ``overrides`` picks the single vector
    (``blind_travel_bearings = 0``, Section 2d) without its own ``blind_travel_view_deg``,
    the vector forgets travel :func:`vector_view_margin_deg` (30°) inside the view.

    Why per bearing at every β, and why no leak: two robots can approach each other from
    outside each other's view while each travels where it looks. Measured (slow test
    ``test_no_collisions_20_episodes[adversarial-8]``: N = 8, β = 120°, robots that drive
    at their nearest teammate, 20 seeds x 1000 steps): with the vector (30°) seed 2 had two
    robots 75-86° off each other's heading close from 1.87 m to contact; per bearing with
    the 30 s leak of ``ControllerParams`` seeds 2, 3 and 17 collided (min 0.42 m), the slow
    creep that the leak forgives adding up over minutes unseen; per bearing without the
    leak none did (min 1.535 m), and with the glance min 1.854 m. The per-bearing budget
    makes a robot that drives straight glance sideways every ~1.3 m at 120°, which the FoV
    levels used to forbid (pfcbf behind the filter, N = 6, seeds 0-19, 1000 steps: 0.9703
    final η and 28.9 s to the normalised threshold, 17 of 20 seeds, with the leak and no
    glance; 0.961, 13.6 s, 16 of 20 without the leak); with the glance 0.9939 and 17.9 s
    (median 11.1 s), 20 of 20 (the vector: 0.9925, 8.61 s; pfcbf alone 0.9955, 7.14 s).
    Without the credit for backing away (``blind_travel_credit_m = 0``, since a neighbour
    that followed a robot unseen was approached 0.9 m blind): 0.9945, 21.3 s (median
    13.7 s), 20 of 20.
    Narrow views stay costly. pfcbf behind the filter, η after 30 s, seeds 0 / 7 / 9, with
    the steady-course look (``look_persistence_deg = 45``, the default): 0.777 / 0.013 /
    0.084 at 45°, 0.991 / 0.766 / 0.981 at 90°; on this release's filter
    (``run_episode("coverage", "pfcbf", seed, safety_filter=True, fov_deg=β,
    max_steps=150)``) 0.730 / 0.011 / 0.084 and 0.991 / 0.614 / 0.976, the same at 45°
    seed 0 and 90° seed 7 with ``blind_travel_prespend`` off. Before the steady-course
    look, with the option
    ``blind_travel_reach`` (safety Section 2f; without it in brackets): at 45° 0.904 /
    0.012 / 0.293 (0.818 / 0.011 / 0.084), at 90° 0.977 / 0.577 / 0.943 (0.991 / 0.549 /
    0.876). An earlier record, on an older filter: 0.98 / 0.41 / 0.99
    at 90° and 0.82 / 0.010 / 0.084 at 45° (alone 0.99 / 0.99 / 0.98 and
    0.985 / 0.45 / 0.87). Before the arc guard could stop a creep to keep the turn
    (``arc_guard_stop``, safety Section 1c) they were 0.53 / 0.38 / 0.42 and 0.40 / 0.011 /
    0.013 (alone 0.98 / 0.95 / 0.91 and 0.95 / 0.033 / 0.40). What still stops the
    robots at 45° (traced, seed 7): the particles of the unseen neighbours lie along the
    edges of the narrow view, so the blind rows (safety Section 2) hold straight ahead;
    the robot glances left and right, and while it looks one way the clouds spread back
    into the other. (Measured since, with the budget's and the blind rows' contributions
    separated, ``ideal`` behind the filter, 150 steps: the budget binds in 50-69% of the
    robot-steps at 45° and ``blind_travel_m = 0`` lifts η after 30 s on seed 7 from 0.04 to
    0.98; wider bins, ``blind_travel_bearings`` 48 or 72, do not help.)

    The budget is at most half the margin to contact, ``B = min(0.5, (D_s − 2 r) / 2)``
    (unless ``overrides`` sets ``blind_travel_m``): a pair that never looks closes by at
    most ``2 B``, so two robots that start at least D_s apart keep clear of contact. 0.5 m
    for the paper's D_s = 2 m and r = 0.5 m. Measured with the fixed 0.5 m (red team,
    ``safety_distance_m = 1.05``, N = 8, random start, ``init="uniform"``, seed 1): the
    ``head_on`` and ``wall_slide`` adversaries collided from starts outside D_s (0.795 m);
    with B = 0.025 m they keep clear (``tests/wrappers/test_safety_filter.py``).
    """
    out = dict(FILTER_CONTROLLER_DEFAULTS)
    if isinstance(overrides, ControllerParams):
        return out  # used as given: the defaults do not matter
    over = dict(overrides) if isinstance(overrides, Mapping) else {}
    try:
        margin = float(config.safety_distance_m) - 2.0 * float(config.robot_radius_m)
        out["blind_travel_m"] = min(out["blind_travel_m"], max(margin, 0.0) / 2.0)
    except (AttributeError, TypeError, ValueError):  # a bad config: make_config reports it
        pass
    if over.get("blind_travel_bearings") == 0 and "blind_travel_view_deg" not in over:
        try:
            out["blind_travel_view_deg"] = vector_view_margin_deg(
                float(config.robot_radius_m), float(config.safety_distance_m)
            )
        except (TypeError, ValueError):  # a bad config: make_config reports it
            pass
    return out


def filter_controller_params(config: Any, value: Any) -> ControllerParams:
    """The filter's :class:`ControllerParams` for the env of ``config``: ``value`` (a
    dataclass, used as given; a dict of overrides; or None) on top of
    :func:`filter_controller_defaults` (one place for both wrappers).

    Raises:
        ValueError: ``config.detection_range_m <= config.safety_distance_m``: a camera
            that cannot see to D_s finds a neighbour only once it is inside D_s, and the
            filter's rows and travel budget keep D_s only for neighbours it can see there
            (red team, N = 8, β = 120°, ``head_on``, random start, seed 46000: with a 1 m
            range, 2 r, three collisions, min 0.843 m; with 2 m and 2.5 m none, but D_s
            broken, min 1.910 / 1.959 m); or a bad ``value``.
    """
    try:
        rng_m, ds_m = float(config.detection_range_m), float(config.safety_distance_m)
    except (AttributeError, TypeError, ValueError):  # a bad config: make_config reports it
        rng_m = ds_m = math.nan
    if rng_m <= ds_m:
        raise ConfigError(
            f"detection_range_m must be above safety_distance_m = {ds_m:g} m behind the "
            f"safety filter, got {rng_m:g}: the camera must see a neighbour before it is "
            "inside D_s (raise detection_range_m or lower safety_distance_m)"
        )
    return check_params(
        "controller_params", value, ControllerParams, filter_controller_defaults(config, value)
    )


def vector_view_margin_deg(robot_radius_m: float, safety_distance_m: float) -> float:
    """``asin(2 r / D_s)`` in degrees (30° for r = 0.5 m, D_s = 2 m): the filter's
    ``blind_travel_view_deg`` when ``blind_travel_bearings = 0`` selects the single budget
    vector (:func:`filter_controller_defaults`). That vector forgets travel whose net direction
    lies at least this far inside the view; a static point outside the view is then at
    least this far off the direction of travel, and one at least D_s away is passed at no
    less than ``D_s sin(asin(2 r / D_s)) = 2 r``: no contact. pfcbf's vector (an ablation
    since pfcbf too keeps its budget per bearing) keeps 10°.

    Measured (one episode each, seed 8000, 300 steps, β = 120°): with 10° the
    ``wait_charge`` adversary (N = 12, random start) crab-walked 30-60° off the bearing of
    a neighbour standing just outside its view, 1.55 -> 1.12 m, and ``head_on`` (N = 8,
    head-on-pair start) reached 1.26 m; with 30° 2.52 m and 2.05 m. pfcbf behind the
    filter kept its coverage (η after 30 s, seeds 0 / 7 / 9: 0.986 / 0.967 / 0.970 against
    0.987 / 0.984 / 0.972 with 10°); with 48.6° (asin((D_s − B)/D_s)) seed 7 fell to 0.63.
    """
    return math.degrees(math.asin(min(1.0, 2.0 * robot_radius_m / safety_distance_m)))


class SafetyFilterWrapper(BaseParallelWrapper):
    """Make any policy's actions safe (see the module docstring).

    Args:
        env: a fov_marl ParallelEnv (``fov_coverage_v0`` / ``fov_crossing_v0``), possibly
            wrapped.
        init: ``"known"`` or ``"uniform"`` particle initialisation.
        tracker_params, controller_params: dataclasses (used as given) or dicts of
            overrides on top of the filter's defaults
            (:data:`FILTER_TRACKER_DEFAULTS`, :data:`FILTER_CONTROLLER_DEFAULTS`).
        draw_robot: robot whose beliefs :meth:`draw` shows, or None for none.
        controller: ``"auto"`` (one :class:`~fov_marl.control.FovCbfController` per robot for
            one team: as fast, and bit for bit the numbers of before), ``"batched"`` or
            ``"loop"`` (:class:`~fov_marl.pipeline.PfCbfPipeline`); same actions within 1e-6.
        tracker_threads: threads that step the particle filters (an int in ``[1, 1024]``,
            default 1; the same actions for every count). One team's filters are too
            small to gain from threads; the option is here so that ``fov-marl train
            --filter-threads`` reaches :class:`VectorSafetyFilterWrapper`, which builds
            its filter from this wrapper's.
    """

    def __init__(
        self,
        env: Any,
        *,
        init: str = "known",
        tracker_params: TrackerParams | dict | None = None,
        controller_params: ControllerParams | dict | None = None,
        draw_robot: int | None = 0,
        controller: str = "auto",
        tracker_threads: int = 1,
    ) -> None:
        base = fov_parallel_base(
            "SafetyFilterWrapper", env, "for B copies use VectorSafetyFilterWrapper"
        )
        super().__init__(env)
        tracker_params = check_params(
            "tracker_params", tracker_params, TrackerParams, FILTER_TRACKER_DEFAULTS
        )
        controller_params = filter_controller_params(base.config, controller_params)
        n = base.config.n_agents
        if draw_robot is not None:
            check_int("draw_robot", draw_robot, 0, n - 1, note="or None")
        self.config = base.config
        self.pipeline = PfCbfPipeline(
            base.config,
            tracker_params=tracker_params,
            controller_params=controller_params,
            init=init,  # type: ignore[arg-type]
            controller=controller,  # type: ignore[arg-type]
            tracker_threads=tracker_threads,
        )
        self.draw_robot = draw_robot
        self._seed_rng = np.random.default_rng()
        self._ready = False
        self._was_reset = False
        self._last_actions: FilteredActions | None = None
        self.last_cpu_s = 0.0

    max_cycles = FORWARDED_MAX_CYCLES

    @property
    def last_actions(self) -> FilteredActions | None:
        """The last step's ``(nominal, applied)`` actions, each ``(N, 3)`` float32 by robot
        index (a finished agent's nominal row is zero), or None before the first step of an
        episode.

        A stateful policy that models its own motion (the ``pfcbf`` policy's particle
        filters and blind travel budget) reads what its robots really did here; each robot
        only learns its own row, the velocity its actuators executed.
        """
        if self._last_actions is None:
            return None
        return FilteredActions(self._last_actions.nominal.copy(), self._last_actions.applied.copy())

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._seed_rng = np.random.default_rng(seed)
        filter_seed = int(self._seed_rng.integers(2**63)) if seed is None else seed
        self.pipeline.reset(obs, seed=filter_seed, initial_poses_world=self.env.unwrapped.poses)
        self._ready = True
        self._was_reset = True
        self._last_actions = None
        reset_safety_infos(infos)
        return obs, infos

    def step(self, actions: dict[str, Any]):
        if not self._ready:
            raise ValueError(
                "step() called on a finished episode; call reset() first"
                if self._was_reset
                else "step() called before reset()"
            )
        base = self.env.unwrapped
        # validate exactly as the env does (shape, NaN, unknown/missing agents)
        act = base._validate_actions(actions)
        cfg = self.config
        t0 = time.perf_counter()
        v, w = action_to_velocity(act, cfg.v_max_mps, cfg.omega_max_radps)
        u_star = np.column_stack([v, w])
        safe = self.pipeline.filter(u_star)
        t_filter = time.perf_counter() - t0
        agents = list(self.env.agents)
        applied = {a: safe[base.agent_name_mapping[a]] for a in agents}
        obs, rew, term, trunc, infos = self.env.step(applied)
        t1 = time.perf_counter()
        if obs:
            self.pipeline.observe(obs)
        t_filter += time.perf_counter() - t1
        res = self.pipeline.last_results
        nominal = np.clip(act, -1.0, 1.0).astype(np.float32)
        self._last_actions = FilteredActions(nominal, np.asarray(safe, dtype=np.float32).copy())
        set_safety_infos(
            infos,
            base.agent_name_mapping,
            nominal,
            safe,
            [r is not None and bool(r.intervened) for r in res],
            [r is not None and bool(r.fallback) for r in res],
            [r.status if r is not None else "no_neighbours" for r in res],
            self.pipeline.last_cause_bits,
        )
        self.last_cpu_s = t_filter
        if not self.env.agents:
            self._ready = False
        return obs, rew, term, trunc, infos

    def draw(self, canvas: Any) -> None:
        """Render layer: the beliefs of robot ``draw_robot`` (particles, ellipses)."""
        if (
            self._ready
            and self.draw_robot is not None
            and self.pipeline.estimates_view() is not None
        ):
            draw_beliefs(canvas, self.pipeline, robots=(self.draw_robot,))
