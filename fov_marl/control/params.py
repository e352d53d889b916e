"""Controller parameters: the choices the paper leaves open for Section VI and VII-A.

All fields are validated on construction; a bad value raises
:class:`~fov_marl.config.ConfigError` (a ``ValueError``) naming the field and its
allowed range. The scenario's physical quantities (β, D_s, R_d, R_s, v_max, ω_max,
arena, density, dt) live in :class:`~fov_marl.config.ScenarioConfig`; this class
holds only the controller's own knobs.

Defaults and where they come from
=================================

===========================  ========  ===============================================
field                        default   source / reason
===========================  ========  ===============================================
``alpha_border_gain``        1.0       γ₁ (1/s) of the border rows' class-K function
                                       ``α_b(h) = γ₁ h + γ₃ h³`` (h in m): the linear term
                                       of Theorem 1 (Eq. 14-15) gives a feasible
                                       exponential recovery from small violations
``alpha_border_cubic``       0.1       γ₃ (1/(m² s)): the authors' cubic (their code:
                                       γ₁ = 0, γ₃ = 1). The growth is what makes a
                                       released neighbour's border rows inactive
                                       (Eq. 17: with ε = h_max, ``h + ε ≥ 113 − 2‖p‖`` m
                                       must outrun the rotation authority
                                       ``≈ 2‖p‖ ω_max``); γ₃ = 0.1 prunes them up to
                                       ‖p‖ ≈ 50 m while a neighbour 3 m outside the
                                       border still asks for a feasible 5.7 m/s rather
                                       than the pure cubic's bang-bang 27 m/s
``alpha_safety_gain``        2.5       linear, 1/s (h in m²). The authors used 5 with a
                                       0.2-0.25 s period: γ·dt = 1-1.25 is at/over the
                                       edge of the discrete-time condition
                                       ``h_{k+1} ≥ (1 − γ dt) h_k``, so any error in the
                                       neighbour's velocity estimate lands inside D_s.
                                       2.5 keeps γ·dt = 0.5 at dt = 0.2 s.
``alpha_range_gain``         1.0       authors' code, linear, 1/s (h in m²)
``slack_slope``              1.0       s of Eq. 16-17 (1/m); authors 1 (a later branch 2)
``slack_zero_below_ds``      True      ε(d) ≡ 0 for d ≤ D_s (see :func:`~fov_marl.control.
                                       cbf.slack`); False gives the paper's raw formula
``fov_margin_m``             0.05      the FoV rows keep j this far inside the sector
                                       borders and range (absorbs the discrete-time
                                       overshoot of the continuous-time CBF)
``safety_model``             ellipse   ``"ellipse"``: collision rows on the uncertainty,
                                       in discrete time, shared, with blind and wall rows
                                       (:mod:`~fov_marl.control.safety`), replacing Eq. 12
                                       row 3; ``"mean"``: the paper's row 3 on the mean
                                       (ablation). Measured with ``"mean"``: collisions
                                       from N = 12 (pfcbf) and for two robots head-on
                                       behind the filter
``safety_risk``              0.01      δ, one-sided risk of each neighbour row: the
                                       separating line sits z = Φ⁻¹(1 − δ) = 2.33 σ_n in
                                       front of the mean (chance constraint, ref. [12])
``safety_gain``              2.5       γ (1/s) of the discrete-time barrier
                                       ``h_{k+1} ≥ (1 − γ dt) h_k`` on the metric rows
                                       (h in m); used as min(γ, 1/dt): beyond γ dt = 1
                                       the barrier would overshoot (γ dt = 0.5 at dt
                                       0.2 s; at dt 0.5 s the default is used as 2).
                                       Measured (filter, random actions, N = 6): 1.0
                                       changed 31% of the actions, 2.5 27%
``safety_hold_band_m``       0.3       b: neighbour rows approach only beyond D_s + b,
                                       hold within the band (unless j's predicted
                                       closing leaves no room), retreat below D_s
                                       (:func:`~fov_marl.control.safety.hold_band`): no
                                       approach/retreat chatter on the estimate's noise
``hold_band_barrier``        True      the band never demands more retreat than the
                                       barrier itself (False: the earlier rows, which
                                       retreated at j's whole predicted closing within
                                       the band; ablation)
``responsibility``           0.5       ρ, share of the pair's admissible closing each
                                       robot takes (both run the same rows)
``blind_bins``               16        K bearing sectors of the blind rows (speed bound
                                       per direction from undetected neighbours'
                                       particles); 0 disables them
``blind_risk``               0.0       expected neighbours per sector tolerated closer
                                       than the sector's representative particle; 0: the
                                       nearest particle (worst case over the belief).
                                       Measured: with 0.01 a robot whose beliefs had gone
                                       diffuse (σ 8 m) drove blind at 1 m/s into a
                                       neighbour it had lost (the chasing adversary, N = 8:
                                       1 contact in 6 episodes; 0 with 0.0)
``blind_density_risk``       0.02      expected undetected neighbours (from the Gaussian
                                       fits) per sector outside the camera's view above
                                       which approaching the sector is forbidden
                                       (:func:`~fov_marl.control.safety.
                                       blind_density_rows`); 0 disables
``last_seen_radius_m``       5.0       a neighbour lost from view gets a row "do not
                                       approach where it was last seen" while that
                                       point is nearer than this and out of view
                                       (:func:`~fov_marl.control.safety.
                                       last_seen_rows`); 0 disables. Measured: a robot
                                       that turned away from a neighbour seen 2.8 m off
                                       backed blind into it 7 s later; the belief's mean
                                       had drifted 14 m away with the coverage mode
``last_seen_max_age_s``      1e6       ... and while it is younger than this (s); no
                                       limit by default: with 10 s the head-on regression
                                       episode 1 (N = 12, β = 120°) collided again
``last_seen_release``        point     when the camera releases a last-seen point:
                                       ``"point"`` in view, or ``"disk"``: its whole
                                       disk of radius z σ_meas in view (the safety
                                       filter's; a point 0.75 m off the truth was
                                       "seen empty" while the neighbour stood outside
                                       a 45° view, and the robot drove into it)
``blind_travel_m``           0.0       B: how far a robot may get (net displacement)
                                       from where it last looked along its direction
                                       of travel before it must look there
                                       (:func:`~fov_marl.control.safety.
                                       blind_travel_step`); 0 disables (the
                                       safety filter uses 0.5 m, pfcbf in
                                       coverage 1.0 m, pfcbf in crossing 0)
``blind_travel_memory_s``    30.0      T: time constant (s) of the leak of the blind
                                       travel (jitter is forgiven, persistence is not);
                                       inf: no leak (the safety filter: with 30 s a
                                       slow blind creep leaked away and two robots
                                       that never saw each other collided, safety
                                       Section 2e)
``blind_travel_view_deg``    10.0      with the single vector: its travel is forgotten
                                       once its net direction lies this far inside the
                                       view (degrees); the safety filter uses
                                       asin(2 r / D_s) = 30° (a static point outside the
                                       view is then passed at ≥ 2 r)
``blind_travel_bearings``    0         K_b: 0 keeps one net-displacement vector
                                       (Section 2d); K_b > 0 budgets the approach
                                       towards K_b world bearings, each reset only
                                       while the camera looks at it (Section 2e;
                                       the safety filter uses 24: forward travel
                                       along a 45° view approached a neighbour just
                                       outside it 0.67 m on a 0.5 m budget)
``blind_travel_credit_m``    0.0       per bearing: the most credit (m) moving away from
                                       a bearing builds towards it; 0: none (a credit
                                       trusts the unseen neighbour to stand still: one
                                       that followed was approached 0.9 m blind on a
                                       0.5 m budget with 0.5 m of credit)
``blind_travel_reach``       False     per bearing: while no neighbour can be within
                                       D_s + 2 B + 2 v_max dt (the disk it can have
                                       reached since its last detection, at v_max),
                                       every bearing counts as looked at (safety
                                       Section 2f, :func:`~fov_marl.control.safety.
                                       reach_clear`); opt-in (measured trade-off
                                       there)
``blind_travel_prespend``    False     per bearing: a bearing reset while the camera
                                       showed a neighbour within D_s (plus its noise
                                       margin) there starts partly spent, ``(D_s −
                                       d) / 2`` (safety Section 2g, :func:`~fov_marl.
                                       control.safety.bearing_travel_floor`); on in
                                       the safety filter (a harsh changed env's
                                       collision needed it), off here: pfcbf's
                                       sweeps were measured without it
``look_fraction``            0.75      the look before the leap turns a robot once this
                                       fraction of B is spent along a bearing it still
                                       approaches (:meth:`~fov_marl.pipeline.
                                       PfCbfPipeline._look_before_leap`), in (0, 1]; 1:
                                       only once the budget is spent (the safety
                                       filter's: measured, random actions, N = 6, 120°:
                                       56.9% changed against 68.8% with 0.75)
``look_persistence_deg``     0.0       > 0: the early look (``look_fraction``) only for a
                                       u* whose translation keeps its course in Σ_w
                                       within this angle from the last step; another
                                       u* looks once the budget is spent. 0: always
                                       early
``look_yields_fov``          False     while the look before the leap turns the robot
                                       (:meth:`~fov_marl.pipeline.PfCbfPipeline.
                                       _look_before_leap`), its FoV levels are left
                                       out for that step (a glance; the collision rows
                                       stay). True for the safety filter: the FoV
                                       levels, which keep a seen neighbour at one edge
                                       of the view, otherwise forbade the glance and
                                       the per-bearing budget stopped the robot
``walls``                    True      arena walls as rows (the commanded velocity is the
                                       one the robot gets; no sliding)
``wall_gain``                2.5       γ_w (1/s) of the wall rows, used as min(γ_w, 1/dt)
``deadlock_turn_deg``        60.0      "keep right" when the collision rows block u*
                                       (:meth:`~fov_marl.control.controller.
                                       FovCbfController._unblock`): four crossing robots
                                       otherwise stop for good at the centre (VII-D,
                                       seed 0); 0 disables (the safety filter's default)
``deadlock_release``         0.5       hysteresis of "keep right": a robot that kept
                                       right keeps right until its solution keeps this
                                       share of u*'s progress (entered below 0.2);
                                       without it a robot near the threshold kept right
                                       on alternate steps and vx flipped sign
``lost_sigma_max_m``         inf       an undetected neighbour whose Gaussian fit has a std
                                       along the line of sight above this (m) gets no
                                       neighbour row; its particles, density and
                                       last-seen rows and the blind travel budget still
                                       bound motion towards it (:mod:`~fov_marl.control.
                                       safety` Section 1). inf: the rows of every
                                       separable neighbour. An ablation: 2 m cut the
                                       filter's random-action change rate from 68% to
                                       53% but lowered its minimum distances (see the
                                       module docstring of ``safety``)
``undetected_quantile``      gaussian  where the line of an *undetected* neighbour sits:
                                       ``"gaussian"``, z σ_n in front of the Gaussian
                                       fit's mean; ``"particles"``, at the particles'
                                       own δ-quantile along the line of sight
                                       (:func:`~fov_marl.control.safety.
                                       particle_halfplane_offsets`). An ablation, not
                                       stress-swept: measured (random actions behind the
                                       filter, N = 6, 5 x 500 steps) 78% of robot-steps
                                       changed against 81% at β = 120°; 2 x 300 steps at
                                       360°: 17% and 15% against 18% and 34%
``bearing_cone_max_deg``     45.0      cap on the half-angle α of the cone of bearings
                                       a neighbour within D_s may lie at: its row gets
                                       two more along the cone's edges (:mod:`~fov_marl.
                                       control.safety` Section 1b), so a robot inside
                                       D_s does not move across an uncertain line of
                                       sight; 0 disables. Measured: without it a packed
                                       robot in the safe fallback closed from 1.043 m
                                       to 1.015 m (contact 1.0) in one step
``fallback_tie_mps``         0.25      rows within this (m/s) of the smallest b̃ tie as
                                       the safe fallback's turn target; the one nearest
                                       the camera's axis wins (no back-and-forth between
                                       two neighbours); 0: the plain argmin
``fallback_straight``        True      a step the safe fallback keeps while a row holds
                                       or retreats has ω = 0 (an arc at ω_max curved a
                                       packed robot from 1.1 m to 1.089 m)
``fallback_escape``          False     the safe fallback projects the QP's input onto
                                       "no row worse than standing still" instead of
                                       stopping when it makes a row worse, and a robot
                                       left without translation turns towards the
                                       escape direction nearest it that its neighbour,
                                       cone and wall rows allow, so that the camera
                                       clears the blind rows there (:mod:`~fov_marl.
                                       control.safety` Section 1f). Measured: robots
                                       packed 1.1 m apart in a corner never moved
``safety_recovery_mps``      inf       below D_s a neighbour row demands retreat at
                                       ``min(γ |h|, r)`` (m/s) instead of ``γ |h|``
                                       (:func:`~fov_marl.control.safety.
                                       neighbour_row_offsets`): a packed pair was
                                       asked for 4 m/s, four times v_max; inf: no cap
``arc_yaw_guard``            True      the output's yaw rate is limited so that the
                                       exact arc of the step approaches no line of
                                       sight a row holds (b ≤ 0) further than the
                                       straight step does (:mod:`~fov_marl.control.
                                       safety` Section 1c; without it a packed pair
                                       creeping while turning closed 1.1 to 1.098 m)
``arc_guard_stop``           True      where the guard would slow the turn and every
                                       row holds at standstill, the robot stops
                                       translating and keeps the turn instead, if that
                                       is the smaller change (``‖Δv‖² + λ² Δω²``);
                                       without it a robot creeping at 0.01 m/s along a
                                       held blind row could not turn to look, and
                                       stood still (pfcbf, β = 45°, seed 7: η 0.06
                                       after 60 s, 0.96 with it)
``hold_cleanup``             True      an output that approaches a held collision row
                                       (b ≤ 0) within the cascade's tolerance is moved
                                       to the nearest input that approaches none
                                       (:func:`~fov_marl.control.controller.
                                       hold_cleanup`), else the safe fallback; off
                                       is an ablation (a packed robot crept 0.13 mm
                                       into an unseen neighbour)
``detection_rows``           False     each detected neighbour also gets a row on the
                                       camera's raw detection with Σ_MEAS (never a
                                       push: approach only), so a posterior that drifts
                                       does not steer the robot into a neighbour it
                                       sees (:mod:`~fov_marl.control.safety` Section
                                       1d); on in ``SafetyFilterWrapper``, off in pfcbf
``detection_cone``           True      with ``detection_rows`` and a bearing cone, the
                                       detection's row also gets the edges of its own
                                       cone of bearings (Σ_MEAS) where the posterior's
                                       cone applies (both within D_s), so a posterior
                                       off the truth does not open a bearing towards a
                                       neighbour the camera sees (Section 1d).
                                       Measured: without it a packed robot in the safe
                                       fallback closed from 1.100 m to 1.096 m
``detection_sector``         False     with ``detection_rows``: a detection reported
                                       outside the camera sector (noise) pushes no
                                       robot away, and the sector's edges and axis
                                       become approach-only rows (:mod:`~fov_marl.
                                       control.safety` Section 1e). Off: the numbers
                                       measured so far; the harsh changed env's
                                       collision (CHANGELOG) needs it
``lost_fov_yield``           True      the FoV levels of neighbours the camera does not
                                       report yield when they stall the robot
                                       (:meth:`~fov_marl.control.controller.
                                       FovCbfController._yield_lost`): a crossing robot
                                       otherwise stood 7 m from its target for 150 s,
                                       pinned by three neighbours lost 25-50 s before
                                       (seed 7); the collision rows stay. Off for the
                                       safety filter (``FILTER_CONTROLLER_DEFAULTS``)
``lost_fov_yield_latch``     True      after a step whose lost FoV levels yielded, the
                                       next step yields them without the stall test
                                       (while u* translates and the yield still halves
                                       the cost): a robot pinned by the blind rows
                                       otherwise turned away (yield), found a free
                                       direction, was turned back by the lost rows and
                                       pinned again, ω flipping every step (settled
                                       pfcbf team, N = 6, seed 3: 7 flips in 250 steps,
                                       0 with it)
``lost_fov_age_s``           10.0      a neighbour counts as lost after this long unseen
                                       (s); yielding the FoV rows of every undetected
                                       neighbour slowed crossing (median arrival 58 s
                                       against 33 s, 20 seeds)
``priority_hysteresis_m``    0.5       Δ: the neighbour that led the FoV levels at the
                                       previous step keeps the lead until another's d_ij
                                       is Δ smaller (Eq. 18's order with hysteresis;
                                       :meth:`~fov_marl.control.controller.
                                       FovCbfController.assign_levels`). Without it a
                                       settled pfcbf robot with two unseen neighbours on
                                       opposite sides, their d_ij within noise of each
                                       other, turned ±0.8 ω_max on alternate steps
``omega_weight``             1.0       λ: Eq. 18-19 minimise ``‖Δv‖² + λ² Δω²``
                                       (λ in s·m/rad... i.e. 1 rad/s of turning costs as
                                       much as λ m/s of translation); 1 is the paper's
                                       ``‖u − u*‖²``
``safety_first``             True      the safety rows of every neighbour form one level
                                       above all FoV levels (False: the paper's per-
                                       neighbour levels, see :mod:`~fov_marl.control.
                                       controller`)
``safety_hard``              False     True: safety rows take no κ (infeasible → brake)
``safety_speed_margin_mps``  0.0       robust margin on the neighbour's speed estimate
                                       (paper: 0); see :func:`~fov_marl.control.cbf.cbf_rows`.
                                       The safety filter keeps 0 (its rows on the
                                       uncertainty assume the neighbour's share)
``fov_recovery_cap``         0.8       c: a FoV row that is violated (h + ε < 0, the
                                       neighbour out of view or its mean beyond R_d) is
                                       *recovered by turning the camera*: its translation
                                       terms are dropped and it demands at most
                                       ``c |A_ω| ω_max`` plus what u*'s translation takes
                                       away (the range row, which rotation cannot repair,
                                       is void); see :mod:`~fov_marl.control.cbf`. 0: the
                                       paper (Theorem 1's recovery with every input).
                                       Measured: the paper's rows dragged crossing robots
                                       8-18 m off their targets (4 robots, Eq. 22: seeds
                                       1, 2 never all arrived, 0, 3, 4 in 46-163 s; with
                                       c = 0.8 all of seeds 0-9 in 35-57 s) and, with the
                                       other changes here, backed a coverage robot blind
                                       into a neighbour (seed 18, 0.94 m; 20 seeds now
                                       ≥ 2.27 m). c < 1 leaves ``(1 − c)`` of the turn
                                       rate to spare
``fov_translation``          "none"    which FoV rows keep their translation terms
                                       (:func:`~fov_marl.control.cbf.cbf_rows`): "all"
                                       (paper, Eq. 17), "seen" (detected neighbours'),
                                       "none" (the camera is kept on neighbours by
                                       turning; translation is u*'s, bounded by the
                                       collision rows): the team at 120° settles
``motion_cone``              False     "look where you go" (not in the paper): a level right
                                       below the safety rows keeps planar speed ≤
                                       ``blind_speed_mps`` outside ±``cone_half_angle_deg``
                                       of the camera axis (:func:`~fov_marl.control.cbf.
                                       motion_cone_rows`). Off for ``pfcbf``
                                       (it deadlocks the dense crossing encounter: a robot
                                       holding a neighbour in view can only creep to its
                                       goal) and for :class:`~fov_marl.wrappers.
                                       SafetyFilterWrapper` (its first version's blanket
                                       cone changed 96% of random actions; the blind
                                       travel budget bounds blind motion instead);
                                       ``controller_params={"motion_cone": True}``
``cone_half_angle_deg``      20.0      a, half-angle of the full-speed cone (capped at β/2);
                                       at 30° off axis 0.22 m/s remain, at 45° 0.11 m/s
``blind_speed_mps``          0.05      v_b: floor of the blind rows (a robot may always
                                       creep at v_b towards where an unseen neighbour may
                                       be, never faster) and the speed allowed in every
                                       direction under the motion cone
``look_gain``                3.0       with the cone: a u* translating outside the
                                       full-speed cone gets ``ω* = sat(look_gain · φ)``,
                                       φ its bearing, so the robot turns to see where it
                                       is sent (1/s; 0 disables)
``max_levels``               3         cap on FoV cascade levels: the two nearest
                                       neighbours with a possibly active row get their
                                       own level, the rest share the third (bounds the
                                       QPs per step: ≤ 2 per level, 4 levels with the
                                       safety level)
``max_fov_neighbours``       8         FoV rows of neighbours ranked beyond this (by d)
                                       are left out (safety rows always stay): bounds
                                       the last level's QP in dense teams
``n_polygon``                16        sides of the polygon inscribed in ``‖v‖ ≤ v_max``
``prune``                    True      drop rows that hold for every admissible input
``qp_backend``               "nnls"    exact active-set least-distance QPs (scipy);
                                       "osqp" kept for comparison (see
                                       :mod:`~fov_marl.control.qp`)
``row_clip``                 10.0      C: normalised row offsets clipped to [−C, C]
``cascade_reg``              1e-3      ρ, weight of ‖u − u*‖² in the cascade QPs (its O(ρ)
                                       bias only touches infeasible levels; smaller ρ
                                       costs NNLS accuracy, ~1e-6 at 1e-3)
``qp_eps``                   1e-6      OSQP eps_abs = eps_rel (osqp backend only)
``qp_max_iter``              4000      OSQP max_iter (osqp backend only)
``intervention_tol``         1e-3      ``intervened`` when ‖u − proj(u*)‖ > tol
``kp_coverage``              0.8       K_p of the Lloyd law (authors' code), 1/s
``k_omega``                  1.0       heading gain of the facing law, 1/s
``face_distance_m``          0.5       below this distance to the goal, ω fades to 0
``lloyd_grid_m``             0.4       Lloyd stencil spacing (see
                                       :func:`~fov_marl.control.benchmark.bench_lloyd_resolution`)
``lloyd_deadband_m``         0.3       Lloyd dead band (not in the paper): the robot
                                       stops within 0.3 m of its estimated centroid
                                       (:func:`~fov_marl.control.coverage.
                                       lloyd_deadband_scale`); 0 is the paper's law
``lloyd_min_mass``           1e-9      cell mass under φ below which u* heads for q_m
===========================  ========  ===============================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from fov_marl.config import ConfigError
from fov_marl.validation import check_bool, check_int, check_real

__all__ = ["ControllerParams", "STALL_FRACTION", "TRANSLATES_FRACTION"]

#: u* translates from this share of v_max on (the stall test, the yield's latch)
TRANSLATES_FRACTION = 0.1
#: the stall test of "keep right" and of the lost rows' yield: the solution keeps less
#: than this share of u*'s progress (``u_v · v̂* < 0.2 ‖v*‖``)
STALL_FRACTION = 0.2


def _check(name: str, value: Any, lo: float, hi: float, *, lo_open: bool = False) -> None:
    check_real(name, value, lo, hi, lo_open=lo_open)


_check_int = check_int
_check_bool = check_bool


@dataclass(frozen=True)
class ControllerParams:
    """Knobs of the FoV-CBF controller and of the coverage law (see module docstring).

    Attributes:
        alpha_border_gain: γ₁ of the border-row class-K function
            ``α_b(h) = γ₁ h + γ₃ h³`` (Eq. 11), 1/s, in [0, 1e6].
        alpha_border_cubic: γ₃ of ``α_b``, 1/(m² s), in [0, 1e6]; γ₁ + γ₃ > 0.
        alpha_safety_gain: γ_s of ``α_s(h) = γ_s h`` for the safety row (1/s), (0, 1e6].
        alpha_range_gain: γ_r of ``α_r(h) = γ_r h`` for the range row (1/s), (0, 1e6].
        slack_slope: s of ``ε = h_max σ(s (d − 3 D_s))`` (1/m), (0, 100].
        slack_zero_below_ds: shift and rescale the sigmoid so ε(D_s) = 0 exactly.
        fov_margin_m: inward margin of the FoV rows (m), in [0, 1].
        safety_model: ``"ellipse"`` (rows of :mod:`fov_marl.control.safety`) or
            ``"mean"`` (Eq. 12 row 3 on the mean, the paper's).
        safety_risk: δ in (0, 0.5), one-sided risk of each neighbour row.
        safety_gain: γ (1/s) of the discrete-time barrier on the metric rows, (0, 1e3];
            the rows use ``min(γ, 1/dt)`` (:func:`~fov_marl.control.safety.barrier_gain`).
        safety_hold_band_m: b in [0, 10] (m), the hold band of the neighbour rows.
        hold_band_barrier: the band caps approach only and never demands more retreat
            than the barrier (:func:`~fov_marl.control.safety.neighbour_row_offsets`);
            False: the earlier rows ``γ g − max((1 − ρ) γ g, p)``, which within the band
            demanded retreat at j's whole predicted closing (ablation).
        responsibility: ρ in (0, 1], share of the admissible closing per robot.
        blind_bins: K in [0, 360] bearing sectors of the blind rows (0: none).
        blind_risk: expected neighbours per sector tolerated, in [0, 1).
        blind_density_risk: Gaussian-mass threshold of the density blind rows, [0, 1).
        last_seen_radius_m: range (m) within which a lost neighbour's last-seen
            point keeps its row, [0, 100]; 0 disables.
        last_seen_max_age_s: age (s) after which a last-seen point is released, (0, 1e6].
        last_seen_release: ``"point"`` or ``"disk"``, when the camera's view releases a
            last-seen point (:func:`~fov_marl.control.safety.last_seen_rows`).
        blind_travel_m: B in [0, 100] (m), the blind travel budget; 0 disables.
        blind_travel_memory_s: T in (0, 1e6] (s) or inf (no leak), the leak of the
            blind travel.
        blind_travel_view_deg: inward margin of the view in [0, 90] (degrees) within which
            the single vector's net travel counts as looked at (Section 2d).
        blind_travel_bearings: K_b in {0} ∪ [4, 360], world bearings of the blind travel
            budget (0: the single net-displacement vector).
        blind_travel_credit_m: F in [0, 100] (m), with the budget per bearing the most
            credit moving away from a bearing builds towards it (Section 2e); 0: none.
        blind_travel_reach: with the budget per bearing, clear it while no
            neighbour's reachable disk comes near the robot (Section 2f).
        blind_travel_prespend: with the budget per bearing, a bearing whose last look
            showed a neighbour within D_s starts with the part of the budget the pair
            has already used (Section 2g).
        walls: add the arena walls as rows.
        wall_gain: γ_w (1/s) of the wall rows, (0, 1e3]; used as ``min(γ_w, 1/dt)``.
        deadlock_turn_deg: turn of u*'s translation (degrees, to the right) tried when
            the collision rows block it, in [0, 180]; 0 disables.
        deadlock_release: in [0.2, 1]: a robot that kept right at the previous step
            keeps right while its solution keeps less than this fraction of u*'s
            progress (a first keep-right needs less than 0.2); 0.2: no hysteresis.
        lost_sigma_max_m: (0, 1e6] or inf (off); undetected neighbours with a larger std along the
            line of sight (m) get no neighbour row.
        undetected_quantile: ``"gaussian"`` or ``"particles"``, the lines of undetected
            neighbours (:func:`~fov_marl.control.safety.safety_rows`).
        bearing_cone_max_deg: cap in [0, 80] (degrees) on the bearing cone of the
            neighbour rows within D_s; 0 disables.
        fallback_tie_mps: in [0, 100] (m/s), rows within this of the smallest b̃ tie as
            the safe fallback's turn target, the one nearest the camera's axis wins.
        fallback_straight: a step the safe fallback keeps while a row holds or
            retreats is straight (ω = 0).
        fallback_escape: the safe fallback escapes rather than stops (Section 1f of
            :mod:`~fov_marl.control.safety`; :func:`~fov_marl.control.controller.
            safe_fallback_inputs`).
        safety_recovery_mps: (0, 100] or inf (m/s), the retreat a neighbour row within
            D_s demands at most (:func:`~fov_marl.control.safety.neighbour_row_offsets`).
        arc_yaw_guard: limit the output's yaw rate so the step's arc approaches no
            held line of sight (:func:`~fov_marl.control.safety.arc_yaw_guard`).
        arc_guard_stop: where the arc guard would slow the turn, stop the translation
            and keep the turn instead when every row holds at standstill and that
            changes the output less (``stop_weight`` of
            :func:`~fov_marl.control.safety.arc_yaw_guard`); False: always slow the turn.
        hold_cleanup: correct an output creeping towards a held collision row within
            the cascade's tolerance (:func:`~fov_marl.control.controller.hold_cleanup`).
        detection_rows: add a row on each detected neighbour's raw detection (the
            camera's report with Σ_MEAS; :func:`~fov_marl.control.safety.detection_rows`),
            which only takes approach away; needs the pipeline's observations.
        detection_cone: with ``detection_rows`` and ``bearing_cone_max_deg > 0``, the
            detection's row gets the edges of its own cone of bearings where its barrier
            and the posterior's are negative (:mod:`~fov_marl.control.safety` Section
            1d); False: ablation.
        detection_sector: with ``detection_rows``, treat a detection reported outside
            the camera sector as the camera contradicting its noise
            (:func:`~fov_marl.control.safety.detection_sector_rows`): no push away, and
            approach-only rows along the sector's edges and axis.
        look_fraction: spent fraction of the blind travel budget (along a bearing u*
            still approaches) from which the look before the leap turns the robot, in
            (0, 1]; 1 (with 1 µm of slack for the float32 actions): once it is spent.
        look_persistence_deg: > 0: the early look applies only while u*'s translation
            keeps its course in Σ_w within this angle (degrees, [0, 180]) of the last
            step's; otherwise the look waits until the budget is spent. 0: off.
        look_yields_fov: leave the FoV rows out of the step of a robot the look before
            the leap turns (``glance`` of :meth:`~fov_marl.control.FovCbfController.solve`).
        lost_fov_yield: when the robot is stalled (less than a fifth of u*'s
            translation kept), solve again without the FoV rows of undetected
            neighbours and use that solution if it is much closer to u*.
        lost_fov_yield_latch: a robot whose lost FoV rows yielded at the previous step
            yields them again without the stall test (``yield_latched`` of
            :meth:`~fov_marl.control.FovCbfController.solve`).
        lost_fov_age_s: seconds unseen after which a neighbour's FoV rows may yield,
            [0, 1e6].
        priority_hysteresis_m: Δ in [0, 100] (m), the head start in d_ij of the
            neighbour that led the FoV levels at the previous step (0: none).
        omega_weight: λ in (0, 10], weight of the yaw rate in the QP metric.
        safety_first: all safety rows form the top cascade level.
        safety_hard: safety rows are hard constraints (no κ); infeasible → brake.
        safety_speed_margin_mps: δv ≥ 0, the safety row is made robust to an error of
            norm ≤ δv in the neighbour's velocity estimate (m/s), [0, 100].
        fov_recovery_cap: c in [0, 1]; FoV rows out of view recover by rotation only,
            demanding at most ``c |A_ω| ω_max`` (0: the paper's rows).
        fov_translation: ``"all"``, ``"seen"`` or ``"none"``: FoV rows that keep
            their translation terms.
        motion_cone: add the "look where you go" level below the safety rows.
        cone_half_angle_deg: half-angle of the full-speed cone, (0, 179] degrees.
        blind_speed_mps: speed allowed outside the cone (m/s), [0, 100].
        look_gain: gain (1/s) turning the robot towards u*'s translation when it points
            outside the cone, [0, 100].
        max_levels: maximum number of FoV cascade levels, in [1, 256]; neighbours
            beyond ``max_levels − 1`` share the last level.
        max_fov_neighbours: neighbours (ranked by d) whose FoV rows may enter the
            hierarchy, in [1, 1024]; safety rows are never left out.
        n_polygon: sides of the regular polygon inscribed in the speed disk, [4, 256].
        prune: drop rows that hold for every admissible input before the QPs.
        qp_backend: ``"nnls"`` (exact active set via scipy) or ``"osqp"`` (see
            :mod:`fov_marl.control.qp` for the measured comparison).
        row_clip: C, normalised row offsets are clipped to [−C, C], in [2, 1e6].
        cascade_reg: ρ, weight of ‖u − u*‖² in the cascade QPs, in [1e-8, 1e-2].
        qp_eps: OSQP absolute and relative tolerance (osqp backend), in (0, 1e-2].
        qp_max_iter: OSQP iteration cap (osqp backend), in [10, 10^6].
        intervention_tol: ‖u − proj(u*)‖ above which ``intervened`` is True (proj: onto
            the speed polygon), [0, 1].
        kp_coverage: K_p of the coverage and crossing proportional laws (1/s), (0, 100].
        k_omega: gain of the facing law (1/s), (0, 100].
        face_distance_m: distance to the goal below which ω fades linearly to 0, (0, 100].
        lloyd_grid_m: spacing of the Lloyd quadrature stencil (m), (0, 2].
        lloyd_deadband_m: dead band of the Lloyd law around the centroid (m), [0, 100].
        lloyd_min_mass: probability mass of the cell under φ below which the robot heads
            for q_m instead of the centroid, in [0, 1).
    """

    alpha_border_gain: float = 1.0
    alpha_border_cubic: float = 0.1
    alpha_safety_gain: float = 2.5
    alpha_range_gain: float = 1.0
    slack_slope: float = 1.0
    slack_zero_below_ds: bool = True
    fov_margin_m: float = 0.05
    safety_model: str = "ellipse"
    safety_risk: float = 0.01
    safety_gain: float = 2.5
    safety_hold_band_m: float = 0.3
    hold_band_barrier: bool = True
    responsibility: float = 0.5
    blind_bins: int = 16
    blind_risk: float = 0.0
    blind_density_risk: float = 0.02
    last_seen_radius_m: float = 5.0
    last_seen_max_age_s: float = 1e6
    last_seen_release: str = "point"
    blind_travel_m: float = 0.0
    blind_travel_memory_s: float = 30.0
    blind_travel_view_deg: float = 10.0
    blind_travel_bearings: int = 0
    blind_travel_credit_m: float = 0.0
    blind_travel_reach: bool = False
    blind_travel_prespend: bool = False
    lost_sigma_max_m: float = math.inf
    undetected_quantile: str = "gaussian"
    bearing_cone_max_deg: float = 45.0
    fallback_tie_mps: float = 0.25
    fallback_straight: bool = True
    fallback_escape: bool = False
    safety_recovery_mps: float = math.inf
    arc_yaw_guard: bool = True
    arc_guard_stop: bool = True
    hold_cleanup: bool = True
    detection_rows: bool = False
    detection_cone: bool = True
    detection_sector: bool = False
    look_fraction: float = 0.75
    look_persistence_deg: float = 0.0
    look_yields_fov: bool = False
    walls: bool = True
    wall_gain: float = 2.5
    deadlock_turn_deg: float = 60.0
    deadlock_release: float = 0.5
    lost_fov_yield: bool = True
    lost_fov_yield_latch: bool = True
    lost_fov_age_s: float = 10.0
    priority_hysteresis_m: float = 0.5
    omega_weight: float = 1.0
    safety_first: bool = True
    safety_hard: bool = False
    safety_speed_margin_mps: float = 0.0
    fov_recovery_cap: float = 0.8
    fov_translation: str = "none"
    motion_cone: bool = False
    cone_half_angle_deg: float = 20.0
    blind_speed_mps: float = 0.05
    look_gain: float = 3.0
    max_levels: int = 3
    max_fov_neighbours: int = 8
    n_polygon: int = 16
    prune: bool = True
    qp_backend: str = "nnls"
    row_clip: float = 10.0
    cascade_reg: float = 1e-3
    qp_eps: float = 1e-6
    qp_max_iter: int = 4000
    intervention_tol: float = 1e-3
    kp_coverage: float = 0.8
    k_omega: float = 1.0
    face_distance_m: float = 0.5
    lloyd_grid_m: float = 0.4
    lloyd_deadband_m: float = 0.3
    lloyd_min_mass: float = 1e-9

    def __post_init__(self) -> None:
        _check("alpha_border_gain", self.alpha_border_gain, 0.0, 1e6)
        _check("alpha_border_cubic", self.alpha_border_cubic, 0.0, 1e6)
        if self.alpha_border_gain + self.alpha_border_cubic <= 0.0:
            raise ConfigError(
                "alpha_border_gain + alpha_border_cubic must be > 0 (a class-K function), "
                f"got {self.alpha_border_gain!r} + {self.alpha_border_cubic!r}"
            )
        _check("alpha_safety_gain", self.alpha_safety_gain, 0.0, 1e6, lo_open=True)
        _check("alpha_range_gain", self.alpha_range_gain, 0.0, 1e6, lo_open=True)
        _check("slack_slope", self.slack_slope, 0.0, 100.0, lo_open=True)
        for name in (
            "slack_zero_below_ds",
            "safety_first",
            "safety_hard",
            "prune",
            "motion_cone",
            "walls",
            "lost_fov_yield",
            "lost_fov_yield_latch",
            "fallback_straight",
            "fallback_escape",
            "arc_yaw_guard",
            "arc_guard_stop",
            "hold_cleanup",
            "look_yields_fov",
            "hold_band_barrier",
            "detection_rows",
            "detection_cone",
            "detection_sector",
            "blind_travel_reach",
            "blind_travel_prespend",
        ):
            _check_bool(name, getattr(self, name))
        _check("fov_margin_m", self.fov_margin_m, 0.0, 1.0)
        if self.fov_translation not in ("all", "seen", "none"):
            raise ConfigError(
                "fov_translation must be one of ('all', 'seen', 'none'), "
                f"got {self.fov_translation!r}"
            )
        if self.last_seen_release not in ("point", "disk"):
            raise ConfigError(
                "last_seen_release must be one of ('point', 'disk'), "
                f"got {self.last_seen_release!r}"
            )
        if self.undetected_quantile not in ("gaussian", "particles"):
            raise ConfigError(
                "undetected_quantile must be one of ('gaussian', 'particles'), "
                f"got {self.undetected_quantile!r}"
            )
        if self.safety_model not in ("ellipse", "mean"):
            raise ConfigError(
                f"safety_model must be one of ('ellipse', 'mean'), got {self.safety_model!r}"
            )
        _check("safety_risk", self.safety_risk, 0.0, 0.5, lo_open=True)
        if self.safety_risk >= 0.5:
            raise ConfigError(f"safety_risk must be in (0.0, 0.5), got {self.safety_risk!r}")
        _check("safety_gain", self.safety_gain, 0.0, 1e3, lo_open=True)
        _check("responsibility", self.responsibility, 0.0, 1.0, lo_open=True)
        _check("safety_hold_band_m", self.safety_hold_band_m, 0.0, 10.0)
        _check_int("blind_bins", self.blind_bins, 0, 360)
        _check("blind_travel_view_deg", self.blind_travel_view_deg, 0.0, 90.0)
        _check_int("blind_travel_bearings", self.blind_travel_bearings, 0, 360)
        _check("blind_travel_credit_m", self.blind_travel_credit_m, 0.0, 100.0)
        if 0 < self.blind_travel_bearings < 4:
            raise ConfigError(
                "blind_travel_bearings must be 0 or in [4, 360], "
                f"got {self.blind_travel_bearings!r}"
            )
        _check("blind_risk", self.blind_risk, 0.0, 1.0)
        if self.blind_risk >= 1.0:
            raise ConfigError(f"blind_risk must be in [0.0, 1.0), got {self.blind_risk!r}")
        _check("wall_gain", self.wall_gain, 0.0, 1e3, lo_open=True)
        _check("blind_density_risk", self.blind_density_risk, 0.0, 1.0)
        _check("last_seen_radius_m", self.last_seen_radius_m, 0.0, 100.0)
        _check("last_seen_max_age_s", self.last_seen_max_age_s, 0.0, 1e6, lo_open=True)
        _check("blind_travel_m", self.blind_travel_m, 0.0, 100.0)
        _check("bearing_cone_max_deg", self.bearing_cone_max_deg, 0.0, 80.0)
        _check("fallback_tie_mps", self.fallback_tie_mps, 0.0, 100.0)
        # inf turns the cut off (the default) / the leak off (the safety filter)
        check_real("lost_sigma_max_m", self.lost_sigma_max_m, 0.0, 1e6, lo_open=True, inf_ok=True)
        check_real(
            "safety_recovery_mps", self.safety_recovery_mps, 0.0, 100.0, lo_open=True, inf_ok=True
        )
        check_real(
            "blind_travel_memory_s", self.blind_travel_memory_s, 0.0, 1e6, lo_open=True, inf_ok=True
        )
        _check("deadlock_turn_deg", self.deadlock_turn_deg, 0.0, 180.0)
        _check("deadlock_release", self.deadlock_release, STALL_FRACTION, 1.0)
        _check("lost_fov_age_s", self.lost_fov_age_s, 0.0, 1e6)
        _check("priority_hysteresis_m", self.priority_hysteresis_m, 0.0, 100.0)
        _check("omega_weight", self.omega_weight, 0.0, 10.0, lo_open=True)
        _check("safety_speed_margin_mps", self.safety_speed_margin_mps, 0.0, 100.0)
        _check("cone_half_angle_deg", self.cone_half_angle_deg, 0.0, 179.0, lo_open=True)
        _check("blind_speed_mps", self.blind_speed_mps, 0.0, 100.0)
        _check("look_gain", self.look_gain, 0.0, 100.0)
        _check("look_fraction", self.look_fraction, 0.0, 1.0, lo_open=True)
        _check("look_persistence_deg", self.look_persistence_deg, 0.0, 180.0)
        _check("fov_recovery_cap", self.fov_recovery_cap, 0.0, 1.0)
        _check_int("max_levels", self.max_levels, 1, 256)
        _check_int("max_fov_neighbours", self.max_fov_neighbours, 1, 1024)
        _check_int("n_polygon", self.n_polygon, 4, 256)
        if self.qp_backend not in ("nnls", "osqp"):
            raise ConfigError(
                f"qp_backend must be one of ('nnls', 'osqp'), got {self.qp_backend!r}"
            )
        _check("row_clip", self.row_clip, 2.0, 1e6)
        _check("cascade_reg", self.cascade_reg, 1e-8, 1e-2)
        _check("qp_eps", self.qp_eps, 0.0, 1e-2, lo_open=True)
        _check_int("qp_max_iter", self.qp_max_iter, 10, 10**6)
        _check("intervention_tol", self.intervention_tol, 0.0, 1.0)
        _check("kp_coverage", self.kp_coverage, 0.0, 100.0, lo_open=True)
        _check("k_omega", self.k_omega, 0.0, 100.0, lo_open=True)
        _check("face_distance_m", self.face_distance_m, 0.0, 100.0, lo_open=True)
        _check("lloyd_grid_m", self.lloyd_grid_m, 0.0, 2.0, lo_open=True)
        _check("lloyd_deadband_m", self.lloyd_deadband_m, 0.0, 100.0)
        _check("lloyd_min_mass", self.lloyd_min_mass, 0.0, 1.0)
        if self.lloyd_min_mass >= 1.0:
            raise ConfigError(f"lloyd_min_mass must be in [0, 1), got {self.lloyd_min_mass!r}")
