"""Collision-avoidance rows on the *uncertainty*, in discrete time, with shared responsibility.

The paper's safety row (Eq. 12, row 3: ``‖ⁱp_j‖² − D_s² ≥ 0``) is written on the
neighbour's *mean*. Measured on the first version of this library, every collision
happened between two robots that did not see each other while the truth was inside
the calibrated 95% ellipse and the mean 3-4 m off. This module replaces that row by
rows built on the neighbour's distribution (the paper's ref. [12], probabilistic
safety barrier certificates), on the camera's knowledge of free space, and on the
arena walls. All rows are *speed bounds along a direction*::

    n · v ≤ s          i.e.  A u + b ≥ 0  with  A = [−n_x, −n_y, 0],  b = s   (m/s)

with ``u = [vx, vy, ω]`` the robot's body-frame input, ``n`` a unit vector in Σ_i.
Pure, vectorised NumPy over robots (leading axis ``R``) and neighbours / bins.

1. Neighbour rows: a separating line per neighbour (chance constraint)
=====================================================================

For neighbour j with estimate ``μ = ⁱμ_j`` and covariance ``Σ = ⁱΣ_j`` (Section V), the
line of sight ``n = μ / ‖μ‖`` and the standard deviation of j's position along it
``σ_n = sqrt(nᵀ Σ n)``. The line ``{q : n·q = s}`` with

    s_j = ‖μ‖ − z σ_n,        z = Φ⁻¹(1 − δ)   (δ = ``safety_risk``)

has j on its far side with probability ``1 − δ`` (Gaussian fit of Section V; one-sided,
so the row is a chance constraint ``P(n · ⁱp_j < s_j) ≤ δ``). The distance from any
point to j is at least its distance to that half-plane, and after robot i moves by
Δ the distance to the half-plane is exactly ``s_j − n·Δ`` (the line is fixed, the
distance to a convex set is convex), so the **discrete-time barrier**

    h_j = s_j − D_s − m_arc,      h_{k+1} ≥ (1 − γ dt) h_k

is met by ``n · Δ_i + n · Δ_j ≤ γ dt h_j``. ``m_arc`` bounds how far the exact unicycle
displacement over dt (an arc, :func:`fov_marl.geometry.integrate_unicycle`) departs
from the straight ``v dt`` (:func:`arc_margin`, 0.030 m at v_max = 1 m/s, ω_max = 1.5
rad/s, dt = 0.2 s).

**Shared responsibility.** Both robots of a pair run the same rows, so each may take
the share ``ρ`` (``responsibility``, 1/2 by default) of the admissible closing
``γ h_j``, as decentralised barrier certificates do. What robot i assumes of j is the
larger of that share and of what j's motion model predicts (its estimated velocity
``ⁱv_j^est``, e.g. Eq. 22's v_max/2 towards i, or the mixture's mean):

    c_j = max((1 − ρ) γ h_j, −n · ⁱv_j^est),      n · v ≤ γ h_j − c_j

so a neighbour predicted to charge is answered in full, and one predicted to stand
still (static model) is assumed to take its share. With γ dt ≤ 1 the pair's
distance to each other's uncertainty band then never drops below ``D_s`` by the
robots' own motion. A negative ``h_j`` demands retreat (the whole ``γ |h_j|`` unless
j's model predicts that it backs off). The hold band (``safety_hold_band_m``,
:func:`hold_band`) caps the approach at ``ρ γ (h_j − b)`` beyond ``D_s + b`` and at 0
within the band, so noise around D_s does not alternate approach and retreat; it only
takes approach away and never adds a retreat the barrier does not demand
(:func:`neighbour_row_offsets`).

Rows are kept for detected neighbours (tight σ_n: the camera's noise) and for
undetected neighbours with ``s_j > 0`` (the robot lies outside j's uncertainty band,
the line separates them). **Only a detected neighbour can push a robot away**: the
row of an undetected one is floored at ``n · v ≤ 0`` (do not approach). Its band
widens every step it stays unseen, and with retreat demanded from every widening
band a settled team at 120° kept pushing itself apart (measured: 160 of 250 steps
of a robot with a binding retreat row, mean speed 0.045 m/s over the last 50 s);
an unseen neighbour runs the same rows and does not approach either, and the FoV
levels turn the camera towards it (its d_ij is small). An undetected neighbour whose band covers the robot
(``s_j ≤ 0``: long unseen, a large ellipse) gives no useful direction: fleeing its mean
is what drove robots backwards, fast and blind, in dense teams. Its particles enter
the blind rows instead. So do, with ``lost_sigma_max_m`` finite (off by default,
an ablation), the undetected neighbours whose std along the line of sight ``σ_n``
exceeds it: a diffuse belief's band reaches close to the robot long before the
neighbour does, and its half-plane ``n · v ≤ 0`` then forbids half the directions.
Measured (random actions behind the filter, N = 6, β = 120°, 2 x 300 steps): such rows
changed 14% of the robot-steps while the true nearest neighbour was a median 13.8 m
away, and 2 m cut the changed share from 68% to 53%; but it lowered the filter's
minimum distances (1.38 m against 2.36 m on the ``wait_charge`` episode below) and,
with ``lost_fov_yield``, let that episode collide (:mod:`fov_marl.wrappers.safety_filter`).

The Gaussian fit of a belief that the camera has cut (Eq. 4 deletes the particles in
view) or stretched along the line of sight can reach much nearer than any particle.
With ``undetected_quantile="particles"`` an undetected neighbour's line sits at the
particles' own δ-quantile of ``n · p`` instead (:func:`particle_halfplane_offsets`):
the same chance constraint, on the belief rather than on its fit. Measured (random
actions behind the filter, N = 6, β = 120°, seeds 10-14 x 500 steps): 78% of the
robot-steps changed against 81% with the Gaussian (lower in 4 of 5 seeds; the rows of
undetected neighbours bind in 27% of the robot-steps against 33%). Most of the rest comes
from the blind rows (44-47%) and the blind travel budget (21-26%): the beliefs of
neighbours unseen for minutes put particles within 3 m of the robot. An ablation,
off by default: not run through the stress sweeps.

1b. Within D_s: the cone of bearings
------------------------------------

The line of a neighbour row is drawn across the *mean's* line of sight, so it says
nothing about the neighbour's bearing. Beyond D_s that costs nothing (D_s − 2 r is the
margin), but within it a move across the estimated line of sight that the row allows
can approach the true neighbour: with σ_t the std of j's position across the line of
sight, the truth may lie up to ``α = asin(min(1, z σ_t / ‖μ‖))`` off it (10-20° for a
detected neighbour at 1.1 m). Measured (``spin_charge`` adversary, N = 8, β = 360°,
robots packed 1.1 m apart along a wall, seed 900): in the safe fallback a robot kept
its QP's escape "across" its neighbour's line at 0.97 m/s, 12° towards the truth, and
the pair closed from 1.043 m to 1.015 m (contact at 1.0) in one step. So for every kept
*detected* neighbour row with ``h_j < 0`` two rows (``ROW_CONE``) are added along the
cone's edges,

    n_±ᵀ v ≤ b_j,     n_± = cos α n ± sin α t,    t ⟂ n,   α ≤ ``bearing_cone_max_deg``

(:func:`bearing_cone`). Where ``b_j ≤ 0`` (hold or retreat) they make the robot's own
motion approach no point of the cone, whatever the bearing in it: ``p · v ≤ 0`` for
every ``p`` in the cone, so a straight step shortens no distance to it. Beyond D_s there
are none, nor for undetected neighbours: a diffuse belief's cone is wide (α at the cap)
and would pin the robot to the retreat directions whenever a band reaches within D_s
(measured: a settled pfcbf team at 120° turned back and forth again), while its row
``n · v ≤ 0`` is already a bound on the distance to the whole half-plane. With them, and with the safe fallback's kept steps made straight
(:meth:`~fov_marl.control.controller.FovCbfController._safe_fallback`: an arc at ω_max
curved a robot escaping across its neighbour's line from 1.1 m to 1.089 m), that
episode's minimum is the start's 1.1 m. Measured over packed starts (wall, corner,
clustered, head-on pairs; N 2-12; β 45/120/360°; all nine adversaries; 2 episodes each
from seed 1100, 864 episodes): 0 collisions; the worst pair came 1.4 mm closer than its
start (β 45° and 120°; none at 360°).

1c. The arc of the step: a bound on the yaw rate
------------------------------------------------

The rows bound the *straight* displacement ``v dt``; the env integrates the exact arc,
``M(φ) v dt = sinc(φ/2) R(φ/2) v dt`` (φ = ω dt, :func:`arc_margin`): ``v`` turned by
φ/2. Beyond D_s the barrier's ``m_arc`` absorbs the difference (Section 1). A row that
holds or retreats (``b ≤ 0``) has no margin left: it lets the robot creep across the
line of sight while it turns, and the arc curves the creep towards the neighbour.
Measured (full stress grid, ``straight``, N = 2, β = 45°, wall start, seed 7000: two
robots packed 1.1 m apart facing the wall, neither seeing the other): each held its
row, crept forward at 0.05 m/s while turning at ω_max, and the pair closed to 1.0981 m.
:func:`arc_yaw_guard` (``ControllerParams.arc_yaw_guard``, default on) therefore
limits the yaw rate of the controller's output, after the QP and keeping its
translation: for every neighbour, blind or bearing-cone row with ``b ≤ 0``, with
``a = n · v`` and ``q = n · J v`` (J: +90°), the arc's component along n,
``sinc(φ/2) (a cos(φ/2) + q sin(φ/2))``, may not exceed ``max(a, 0) + ε``
(ε = 1e-6 m/s): no approach where the straight step approaches none, and no more than
it where round-off lets it. ``φ = 0`` always qualifies (the straight step the QP
approved), so the bound never makes anything infeasible; it binds only while a robot
translates across a held line of sight, and then only the turn towards that line is
slowed. The bearing cone's edges (Section 1b) are rows too, so the step approaches no
bearing of the cone (a sinusoid below 0 at both ends of an arc shorter than π is below
0 on it). Measured on the alternative, turned copies of the hold rows in the QP: they
made the safety level infeasible more often (pfcbf, N = 6, β = 120°, seed 1: 15-19 safe
fallbacks in 2,400 robot-steps against 4) and turned a settled robot back and forth.

Slowing the turn is not the only safe repair: an input without translation approaches
nothing, whatever its arc. Where the guard would slow the turn and every row holds at
standstill (``A (0, 0, ω) + b ≥ 0``: no row asks for a retreat), the robot stops
translating and keeps its turn instead, when that is the smaller change in the QP's
metric, ``‖v‖² < λ² (ω − ω_slowed)²`` (``ControllerParams.arc_guard_stop``, default on;
``stop_weight`` of :func:`arc_yaw_guard`). It matters for narrow views. Measured (pfcbf,
N = 6, β = 45°, seed 7): a blind row straight ahead held, the QP kept a 0.01 m/s creep
along it together with the look turn (Section 2d), and the guard slowed the turn to
nothing, so the robot neither moved nor looked; all six stood still, η 0.06 after
60 s. With the stop they turn to look: η 0.96. Behind the safety filter at 90° (seeds
0 / 7 / 9, η after 30 s): 0.53 / 0.38 / 0.42 before, 0.98 / 0.41 / 0.99 with it.

1d. The camera's own report
---------------------------

The row of a *detected* neighbour is drawn on its posterior (Section V), and a
posterior can be wrong while the camera is right. Measured (red team 9: the
``chase_last_seen`` adversary, N = 8, β = 360°, robots packed 1.1 m apart along a wall,
seed 43201, detection noise ``meas_cov_diag = (0.5, 0.5, 1.0)``, 500 particles): robot 2
saw robot 1 1.1 m ahead every step, but its posterior (a spurious constant-velocity
mode) drifted through robot 2 itself, to (−0.08, 0) m. The row's line of sight then
pointed backwards, its retreat asked for full speed *forward*, the safe fallback kept
that step, and robot 2 drove into robot 1 (0.508 m). A 0.5 m bias at 0.71 m noise is
0.7 σ of one detection: the tracker's bias test cannot see it in time. With
``ControllerParams.detection_rows`` (:func:`detection_rows`) each detected neighbour
also gets the same chance constraint on the raw detection ``z`` with the camera's own
covariance Σ_MEAS, which does not depend on the tracker:

    n_z · v ≤ max(0, ρ γ h_z),   h_z = ‖z‖ − z_δ σ_z − D_s − m_arc,
    n_z = z / ‖z‖,   σ_z² = n_zᵀ Σ_MEAS n_z

It only takes approach away (the floor at 0): the robot never closes on where its
camera sees a neighbour faster than the shared barrier allows, whatever its filter
believes, and one noisy detection never pushes it (the posterior's row does the
pushing). Where the two disagree, as above, the safety level is infeasible and the safe
fallback stops the translation. The price is a larger margin towards seen neighbours
while approaching: at the default noise (σ = 0.32 m, z_δ = 2.33) approach ends where the
detection is 2.77 m away, instead of where the posterior's band (std ~0.1-0.2 m) is
D_s away. On in :class:`~fov_marl.wrappers.SafetyFilterWrapper`
(:data:`~fov_marl.wrappers.safety_filter.FILTER_CONTROLLER_DEFAULTS`), off in
:class:`~fov_marl.control.params.ControllerParams` and so in pfcbf, whose acceptance
sweeps (hours) were measured without it. Measured with the
filter's defaults (2000 particles), against the same runs without the rows: the stress
sweep of 432 episodes (nine adversaries, N 2/8/12/24, β 45/120/360°, four starts, seed
50000) had no collision either way, and its minimum distance from open starts rose from
1.873 m (random; one D_s event) and 2.186 m (head-on pairs) to 2.316 m and 2.345 m (no
D_s event), at the same intervention rates (0.921 and 0.936); pfcbf behind the filter
(N = 6, seeds 0-19, 1000 steps) reached the normalised threshold in 9.63 s against
9.61 s, final η 0.9954 against 0.9955. The red-team episode keeps its 1.1 m start
spacing (``tests/test_safety_acceptance.py``), and so does the stress grid's seed-17000
collision (one outlying detection re-seeded a neighbour's cloud onto the robot itself,
``TrackerParams.ess_recovery``) run on the tracker without its fused recovery.

The cone of bearings of Section 1b is drawn around the posterior's mean, so the same
disagreement opens a bearing: a posterior outside its own ellipse puts the truth
outside its cone. Measured (issue 10's grid, ``straight`` and every other adversary,
N = 24, β = 360°, robots packed 1.1 m apart in a corner, seed 60001): at step 5 robot
18's posterior of robot 16, 1.1 m away and detected, was 0.70 m and 37° off the truth,
outside its 95% ellipse; the detection was 32° off it. In the safe fallback robot 18
kept its QP's escape at 1 m/s, 84° from the true bearing and 30° outside the
posterior's cone, and the pair closed from 1.100 m to 1.096 m in one step. So with
``ControllerParams.detection_cone`` (default on; it acts only with the detection rows
and a bearing cone) each detection row gets the two edges of the *detection's* cone,
``α_z = asin(min(1, z_δ σ_t / ‖z‖))`` with σ_t the camera's std across the line of
sight, capped at ``bearing_cone_max_deg`` (43° at 1.1 m), with the detection row's ``b``
(0 there: approach only, never a push), where both the detection's barrier ``h_z`` and
the posterior's ``h_j`` are negative: only where the posterior's own cone applies. The
robot then approaches no bearing of either cone; robot 18 stops translating and turns,
and the episode keeps its 1.1 m spacing (``tests/test_safety_acceptance.py``). The cone
was first added wherever ``h_z < 0`` (a detection within 2.77 m at the default noise,
where the posterior's band reaches D_s only within ~2.4 m): the learned policy behind
the filter then lost 0.0036 of final η (N = 6, seeds 0-19: 0.9928 against 0.9964
without the cone, lower in 15 of 20 seeds); with the posterior's condition 0.9969
(3 seeds differ). Stress grid (every adversary, N 2-24, β 45-360°, all starts, seed
60000): 0 collisions and every packed start at 1.100 m with either rule (1,520 and 760
episodes), no D_s event from an open start.

1e. A report the camera contradicts (option)
--------------------------------------------

The camera reports j only while j's true position lies in the sector F_i, and its noise
is clipped per axis, so a detected j lies in ``F_i ∩ box(ⁱz_j, clip)``. When the noise is
of the order of the range the report can fall outside F_i, and then its line of sight
may point away from j: measured in a changed env (``v_max_mps = 2``, ``dt_s = 0.4``,
``detection_range_m = 4``, ``meas_cov_diag = (0.5, 0.5, 0.5)``: 0.71 m per axis, clipped
at 3.5 m), two robots packed 1.1 m apart along a wall, ``straight`` seed 81101: robot 0's
camera reported its neighbour 1.05 m *behind* it while it stood 1.27 m ahead, in view;
the neighbour row demanded a retreat from the report, the safe fallback kept the QP's
full-speed step forward, and the pair collided (1.266 m to 0.472 m). With
``ControllerParams.detection_sector`` (off by default: the numbers measured so far are
without it) such a report pushes nobody (its neighbour row's offset is floored at 0,
before the cone takes it) and the sector's edges and axis, ``θ ∈ {−β/2, 0, β/2}``,
become approach-only rows with the distance to the clip box as clearance
(:func:`detection_sector_rows`): with β ≤ π the robot approaches no bearing of F_i,
with β > π it does not translate towards anything. β = 2π has nothing to contradict.

1f. Robots packed inside D_s: a capped recovery and an escaping fallback (options)
------------------------------------------------------------------------------

Robots that start 1.1 m apart (the stress starts ``corner`` and ``wall``, D_s = 2 m) sit
deep inside each other's barrier: with γ = 2.5 1/s a detected neighbour's row demands
a retreat of ``γ |h| ≈ 4 m/s``, four times v_max, so the collision rows can never all
be met, every packed robot takes the safe fallback, and the plain fallback (keep the
QP's least-violation input only if it makes no row worse than standing still, else
stop and turn to the most dangerous row) stops them all. Measured on this library's
safety filter: from a packed wall or corner no robot of the team ever moved, whatever
the policy behind it (pfcbf, ``ideal``, the learned one; N = 6, β = 120°, 500 steps),
and pfcbf alone stayed in a packed corner (seed 0). Two options (off by default) address it:

* ``ControllerParams.safety_recovery_mps`` r caps the retreat a row demands below
  D_s: ``γ h`` becomes ``max(γ h, −r)`` in :func:`neighbour_row_offsets` (the barrier's
  class-K function saturates). ``h`` still does not decrease, so a packed pair never
  closes; only the rate at which D_s is regained is bounded, and a robot with
  neighbours on one side can meet its rows and use its QP (FoV levels and u*) again.
* ``ControllerParams.fallback_escape``: where the QP's input makes a row worse, the
  fallback projects the *desired* input u* onto "no row worse than standing still"
  (:func:`~fov_marl.control.controller.escape_translation`, the very set the plain
  fallback accepts the QP's input from) instead of stopping, and a robot left without
  translation turns towards the direction nearest u*'s that its neighbour, cone and
  wall rows allow (:func:`~fov_marl.control.controller.escape_heading`) rather than
  towards the most dangerous row: the blind rows there (budget, particles, last-seen
  points) lapse once the camera looks, and a later step can leave. (Aiming at the QP's
  least-violation input instead, robots packed along a wall and rushing to one point
  turned away from where they were sent.)

Measured with both (r = 0.25 m/s), N = 6, β = 120°, 500 steps, seeds 0 / 1 (η at the
end; the plain fallback in brackets): pfcbf alone, packed corner 0.897 / 0.196 (0.000 /
0.888), packed wall 0.980 / 0.987 (0.991 / 0.990); pfcbf behind the filter, options in
both, packed wall 0.917 / 0.896 (0 / 0), packed corner 0 / 0 (0 / 0). So they free some
teams and cost others (pfcbf's corner, seed 1): they stay off. What still holds robots:
the budget per bearing (Sections 2e, 2g) leaves a robot packed beside a neighbour no
out-of-view bearing within ~60° of the neighbour's, so it may leave only straight away
from it or towards what it sees, and a policy that turns it back towards its goal
(``rush``: no robot of 6 got 2 m from a packed wall or corner start in 300 steps, seeds
0-3, with or without the options) or the FoV levels of pfcbf (turn to keep the
neighbours behind in view) undo the escape turn step after step; the robots inside a
corner lattice are boxed in by walls and neighbours until the outer ones leave. No
packed pair closed in any of these episodes (min 1.100 m), nor in the packed stress
sweep with both options (every adversary, N, β of the grid, wall and corner starts, 360
episodes, ``fov-marl stress --starts wall,corner --episodes 1 --seed 91000 --filter-
controller fallback_escape=true --filter-controller safety_recovery_mps=0.25``).

2. Blind rows: a speed bound per direction from the particles (Eq. 4)
====================================================================

The camera reports every neighbour inside F_i, so the particles of undetected
neighbours lie outside F_i (deletion, Eq. 4): they are exactly the belief about what
the robot cannot see. Around the robot, ``K = blind_bins`` bearing sectors; in sector
k the particles of undetected neighbours are sorted by range and the *representative*
``p_k`` is the first one at which the expected number of neighbours closer than it in
that sector (each particle weighing ``1 / P_j``) exceeds ``blind_risk`` (default 0:
the nearest particle, i.e. the support of the belief rather than a quantile; a
quantile lets a robot whose beliefs went diffuse drive blind at full speed, since a
spread-out cloud puts little mass anywhere, and an adversary that seeks its
neighbours is exactly where that little mass is). Its row

    n_k · v ≤ max(v_b [h_k > 0], ρ γ h_k),     h_k = ‖p_k‖ − D_s − m_arc,  n_k = p_k / ‖p_k‖

bounds the speed towards where a neighbour may be, as hard as it is close: never
below ``v_b = blind_speed_mps`` while the representative is beyond D_s (a robot may
creep), never above 0 within it (measured: with the v_b floor everywhere, a robot
packed 1.1 m from a neighbour behind it crept into contact in 15 steps). A robot may
always stop and turn, and it is never pushed around by diffuse beliefs. Directions the camera sees hold no particle
of an undetected neighbour, so they get no row: a robot may drive fast where it looks,
and where its beliefs say nobody is; it slows where an unseen neighbour may be. (This
replaces the first version's blanket "motion cone".)

2b. Blind rows from the Gaussian fits
------------------------------------

In dense teams the fixed budget spreads thin (P_T = 2000 over 23 neighbours: ~90
particles for a neighbour lost from view, whose cloud grows to σ ≈ 10 m), and no
particle need fall in the sector where the neighbour really is. Measured (pfcbf,
N = 24 and 48 in the 40 m arena): robots crept blind into neighbours 1 m away that
way. :func:`blind_density_rows` adds, per sector outside the camera's view, the
expected number of undetected neighbours from their Gaussian fits (Section V) and
forbids approaching the sector (``n_k · v ≤ 0``) where it exceeds
``blind_density_risk``. In a sparse team (N = 6 in the 40 m arena) the sum stays
below it, so it does not add to the interventions there.

2c. Last-seen rows
------------------

The belief about a neighbour lost from view can drift far from it: the mixture's
coverage mode (Eq. 20) carries most particles towards the density peak. Measured
(filter, head-on adversary, N = 12, β = 120°, episode 2): robot 3 lost robot 0 at
2.8 m, turned away, and 7 s later backed blind at 0.9 m/s into it; the Gaussian fit's
mean was 14 m away and no particle lay in the sector it backed into. What the robot
knows for sure is where it last saw the neighbour. :func:`last_seen_rows` keeps, for
each undetected neighbour whose last-seen point ``c`` (world frame, carried into Σ_i
with the robot's own pose) is nearer than ``last_seen_radius_m`` and out of the
camera's view, the row

    n_c · v ≤ max(0, ρ γ h_c),   h_c = ‖c‖ − (z σ_meas + v_max τ) − D_s − m_arc,   n_c = c / ‖c‖

with τ the time since the last detection: approach the point only while the disk the
neighbour can have reached since lies beyond D_s, never afterwards, and never be
pushed by it. A point inside the camera's view is released (the camera shows the
neighbour is not there); so is a point older than ``last_seen_max_age_s`` (no limit
by default: with 10 s the head-on regression episode 1 collided again). The point is
only as good as the estimate it was taken from: with ``last_seen_release="disk"`` (the
safety filter's) it is released only when its whole disk of radius ``z σ_meas`` lies
in view (bearing within ``β/2 − asin(z σ_meas / ‖c‖)``, range within ``R_d − z σ_meas``).
Measured (red team 9, 500 particles, ``dt_s = 0.4``, ``head_on``, N = 8, β = 45°,
clustered, seed 43600): a packed robot's last-seen point of a neighbour 1.45 m away,
the posterior's mean at its last detection, lay 0.75 m off the truth at −6°, inside
the 45° view while the neighbour stood at −47°; released, the robot later translated
blind into it (0.864 m). With the disk rule the pair keeps its start spacing. Only the
direction towards the point is forbidden: the robot may still move away from it,
sideways, or forward where it looks.

2d. Blind travel budget ("look before you leap")
-----------------------------------------------

A neighbour the robot has never seen, or lost long ago, has a belief close to its
prior: spread over the arena, sparse in particles, its mean far away. No row above
then bounds motion towards it. Measured (filter, head-on adversary, N = 12, β = 120°,
episode 1): robot 1 slid sideways at 1 m/s for 2 s into robot 6, stationary just
outside its view, which it had not seen in 26 s; the nearest particle in that sector
was beyond 2.8 m. What the robot knows is what it has looked at. Each robot keeps its
world-frame net displacement ``e`` since it last looked in the direction of ``e``
(:func:`blind_travel_step` adds every step's translation, :func:`blind_travel_reset`
zeroes ``e`` when its bearing comes within the camera's view), and the row

    n_e · v ≤ max(0, (B − ‖e‖) / dt),     n_e = e / ‖e‖ in Σ_i,   B = ``blind_travel_m``

lets it get at most ``B`` further from where it last looked along that direction
(B = 1 m for ``pfcbf`` in coverage, where dense teams slid blind into neighbours never
seen; 0.5 m for ``SafetyFilterWrapper``, whose 1 m let an adversary drive along the edge
of a 45° view into a neighbour parked just outside it, see
:mod:`fov_marl.wrappers.safety_filter`; off for ``pfcbf`` in crossing, whose robots it
stalled: :data:`fov_marl.baselines.pfcbf.PFCBF_COVERAGE_DEFAULTS`).
Net displacement, not path length: jitter cancels, and moving back undoes travel.
``e`` leaks with time constant ``T`` (``blind_travel_memory_s``, 30 s: the creep it
allows, ``B (1 − λ) / dt`` with ``λ = e^{−dt/T}``, is 0.03 m/s; the safety filter has
none, Section 2e). When ``‖e‖ ≥ ¾ B`` and
u* keeps translating along ``e``, the pipeline turns the robot to look that way
(:meth:`fov_marl.pipeline.PfCbfPipeline._look_before_leap`), which releases the budget.
Measured (random actions behind the filter, N = 6, β = 120°, 2 × 150 steps): changed
robot-steps 38% without the budget, 43% with it; counting only the displacement made
outside the view (path length in blind directions) gave 59%. With it, the episode
above and its neighbour (episode 2, a robot backing into one it had turned away
from) no longer collide.

2e. Blind travel per bearing
----------------------------

The budget of Section 2d counts travel *along* ``e`` as looked at whenever ``e``'s
bearing is in view. A robot is a disk, not a point: a step Δ approaches every point
at bearing ψ by ``n_ψ · Δ``, and for a camera narrower than 180° the bearings just
outside the view are approached almost as fast as the direction of travel (``cos
(β/2)``, 0.92 at β = 45°). Measured (``SafetyFilterWrapper``, ``wait_charge``, N = 24,
β = 45°, ``head_on_pair`` start, seed 300, steps 205-245): a robot drove forward, in
view, in bursts of 0.75 m/s towards a neighbour parked 2.08 m away at a bearing of
−34° to −38° that it had not seen for 40 s (its belief: mean 8 m away, std 9 m);
``e`` was zeroed every step it drove forward, and it closed to 1.41 m, 0.67 m of
blind approach on a 0.5 m budget. With ``blind_travel_bearings = K_b > 0``
(``ControllerParams``) the robot keeps instead, for K_b fixed world bearings ``n_k``,
the approach made towards each since the camera last looked at it
(:func:`bearing_travel_step`, :func:`bearing_travel_reset`)::

    c_k ← max(0, λ c_k + n_k · Δ),      c_k ← 0 while the bin's sector is in view,
                                         |bearing of n_k in Σ_i| ≤ β/2 − π/K_b

and one row per bearing (:func:`bearing_travel_rows`)

    n_k · v ≤ max(0, (B − c_k) / dt)

written only where it can bind (``B − c_k < v_max dt``). So no bearing the camera has
not looked at is approached by more than ``B`` (plus one step, and the bins' spacing:
a bearing between two bins is approached at most ``1 / cos(π / K_b)`` times as fast
as the nearer bin allows) between two looks, whichever way the robot travels;
travel along ``e`` is the special case of the bearing of ``e``, so the rows bound at
least what the single vector bounds. Moving away from a bearing earns no credit
towards it (the ``0`` floor; ``ControllerParams.blind_travel_credit_m``): a credit
assumes the unseen neighbour stands still, and one that follows the robot is then
approached by the credit *plus* ``B``. Measured with a credit of ``B`` (the previous
release; ``head_on`` adversary, N = 12, β = 120°, ``head_on_pair`` start, seed 9000,
the only D_s breach from a start outside D_s in the full stress grid): a robot had
backed 0.49 m away from a bearing while the head-on neighbour there followed it, then
drove 0.9 m towards it without looking, from 2.51 m to 1.654 m; without the credit
the episode keeps 2.426 m. Its cost (pfcbf behind the filter, N = 6, seeds 0-19,
1000 steps): final η 0.9945 against 0.9939, time to the normalised threshold 21.3 s
(median 13.7) against 17.9 s (median 11.1), 60.4% of robot-steps changed against
58.5%. Δ is the step's exact arc. Measured (random actions behind the filter, N = 6,
β = 120°, seeds 10-14 x 300 steps, with the credit): 75% of the robot-steps changed
against 73% with the single vector (2 x 150 steps,
``tests/wrappers/test_safety_filter.py``: 67% against 50%; K_b = 12 / 36 no fewer).
The pipeline
turns the robot towards the most-spent bearing that u* approaches when ``c_k ≥ ¾ B``
(``ControllerParams.look_fraction``;
:meth:`fov_marl.pipeline.PfCbfPipeline._look_before_leap`); in the safety filter that
early look is only for a u* that keeps its course in Σ_w within 45° of the last step's
(``look_persistence_deg``), any other u* looks once the bearing is spent (``c_k ≥ B``):
the look only turns the robot, the rows above bound the travel either way. The safety filter uses
K_b = 24 (15°: the bins cost at most 0.9%) at every β, with no leak
(``blind_travel_memory_s = inf``), and lets that turn outrank the FoV levels for the
step (``look_yields_fov``, a glance; the collision rows stay):
:func:`fov_marl.wrappers.safety_filter.filter_controller_defaults`.

Why the projection, and not the distance to what the last look showed. For a neighbour
that stands still, the projection overcounts: driving straight past a point at bearing
ψ closes on it by at most ``d (1 − sin ψ)`` in all, while the row books ``s cos ψ``
per ``s`` driven, without end (hence the glance every ~1.3 m below). But the row must
also hold for a neighbour that moves. For robots i and j at ``p_i``, ``p_j``, with
``n_0`` the unit vector from i to j when the budgets last started counting and ``Δ_i``,
``Δ_j`` the displacements since, the triangle inequality gives

    d_0 − d_1 ≤ n_0 · Δ_i + (−n_0) · Δ_j,

each robot's projection on its own fixed world bearing towards the other: exactly what
the two rows bound (by B each). The bound is tight for a j that follows i at a constant
bearing (``p_j − p_i`` stays parallel to ``n_0``), and then i's share is its
projection ``s cos ψ``, whatever i saw: a rule that books i less for that direction (the
distance to a static point, or to the half-line its last look showed empty) leaves that
follower free to close by more than ``2 B``. The stress sweeps' ``chase_last_seen`` and
``head_on`` adversaries are such followers.

Why per bearing also for wide views, and why no leak. The single vector is blind to a
neighbour that moves: two robots may each travel where they look and still approach
each other from outside each other's view. Measured (the filter, robots that drive at
their nearest teammate, N = 8, β = 120°, seed 2): two robots 75-86° off each other's
heading closed at 0.5-0.6 m/s each, from 1.87 m to contact, both with the vector
zeroed every step. Per bearing, each robot's approach towards every bearing it has not
looked at is bounded by ``B``, so a pair that never looks closes by at most ``2 B``
(plus the bins' spacing) -- but only without the leak: with ``T = 30 s`` the creep of
``B / T`` per robot that the leak forgives added up over minutes unseen, and three of
20 such episodes collided (min 0.42 m); without it none did (min 1.535 m; 1.854 m with
the glance). The price is that a robot driving straight must glance sideways every
~1.3 m at 120° (the bearings 67.5° off its heading, approached at 0.38 per metre, are
never in view). The FoV levels, which keep a seen neighbour at one edge of the view,
forbade those glances, and the budget then stopped the robot: pfcbf behind the filter
(N = 6, seeds 0-19, 1000 steps) reached the normalised threshold in 28.9 s (17 of 20)
with the leak and without the glance; with the glance in 17.9 s (median 11 s), 20 of
20, final η 0.9939 (the vector: 8.61 s, 0.9925; pfcbf alone 7.14 s, 0.9955). Narrow
views still cost more (:func:`fov_marl.wrappers.safety_filter.filter_controller_defaults`).
An explicit ``blind_travel_bearings =
0`` selects the vector, which then forgets travel only ``asin(2 r / D_s)`` = 30° inside
the view (``blind_travel_view_deg``,
:func:`fov_marl.wrappers.safety_filter.vector_view_margin_deg`): a *static* point
outside the view and at least D_s away is then passed at no less than 2 r (with 10°,
an adversary crab-walking at β/2 − 10° went from 1.55 to 1.12 m towards one at 120°).
``pfcbf`` in coverage keeps its budget per bearing too, with the glance, B = 1 m and a
120 s leak (:data:`fov_marl.baselines.pfcbf.PFCBF_COVERAGE_DEFAULTS`): on the vector, two
robots of a 200-robot team that never saw each other each slid 49° off their heading
(inside the view less the vector's 10° margin) and closed from 2.86 m to 0.994 m.

2f. Nobody near: every bearing counts as looked at
--------------------------------------------------

A look clears a bearing because it shows nobody there. What the robot knows without
looking can clear them all: neighbour j was last *detected* at ``z`` (world frame) and
moves at most ``v_max``, so ``τ`` seconds later it lies in the disk

    D_j = disk(z, r_z + v_max τ),    r_z = c_clip ‖(σ_x, σ_y)‖

with ``c_clip = meas_noise_clip_sigma`` (the env truncates its detection noise there,
so the disk holds j surely, not with a probability; the known start poses of
``init="known"`` count as detections at t = 0 with ``r_z = 0``; a neighbour never
detected has no disk and may be anywhere). With ``ControllerParams.blind_travel_reach``
the pipeline zeroes every ``c_k`` of a robot while all its neighbours' disks lie farther
than ``H = D_s + 2 B + 2 v_max dt`` (:func:`reach_clear`): nobody can be within H in
any direction, which is more than a look shows (the view, not the whole circle). When
the budget starts counting again every neighbour is at least ``H − 2 v_max dt = D_s +
2 B`` away, and after the robot and the neighbour each spend their budget B towards
each other the pair is still D_s apart (a look promises contact only, ``D_s − 2 B =
2 r``). A robot whose neighbours were seen recently and far away no longer spends its
budget, nor glances, for nothing. Off by default (in pfcbf, whose sweeps were measured
without it, and in the safety filter, where the shipped learned policy, trained without
it, lost its final-η lead over pfcbf with it: :mod:`fov_marl.wrappers.safety_filter`);
the filter's sweeps with it on are in the CHANGELOG.

Clearing per bearing instead (every bearing more than ``asin(r_j / d_j)`` plus a bin
off every near disk) was tried and not kept: it changed fewer random actions (49%
against 59%, N = 6, β = 120°, 2 x 150 steps) but pfcbf behind the filter settled worse
(N = 6, β = 120°, seeds 0-19, 1000 steps: final η 0.9933 against 0.9954 without the
rule, 4 seeds below 0.99, mean time to settle 158 s against 110 s; with this rule 0.9955,
all 20 above 0.99, 135 s), and it rests on the
bins' caveat of Section 2e (a neighbour moving sideways into a bearing cleared while it
stood elsewhere meets a fresh budget there), which this rule does not.

2g. A bearing that saw a neighbour inside D_s starts spent
----------------------------------------------------------

The budget's bound, ``d_0 − d_1 ≤ n_0 · Δ_i + (−n_0) · Δ_j ≤ 2 B``, keeps a pair apart
only if it started at least ``D_s − 2 B`` (contact, 1 m) plus ``2 B`` apart, i.e. at
``D_s``: a bearing reset while the camera showed a neighbour *inside* D_s there gets a
fresh budget B it cannot afford. Measured (the harsh changed env of Section 1e,
``head_on`` seed 81100, two robots packed along a wall, 1.165 m apart): robot 0 saw
robot 1 behind its left shoulder for 27 steps, turned away, and 96 s later backed 0.42 m
in one 0.4 s step into it (1.13 m to 0.714 m); the bearing's budget was unspent
(``c = 0.009``), the belief spread over the arena, and no particle lay behind within
1.6 m. With ``ControllerParams.blind_travel_prespend`` (on in the safety filter; off in
``ControllerParams`` and so in pfcbf, whose sweeps were measured without it) each bearing
keeps, besides ``c_k``, the part of its budget the neighbours seen there at its last
look had already used (:func:`bearing_travel_floor`)::

    f_k = max_j  clip((D_s − d_j) / 2, 0, B)     over the j whose cone holds bearing k,
    d_j = ‖ⁱz_j‖ − r_j,   r_j = z_δ σ_max,   cone: |ψ_k − ψ_j| ≤ asin(min(1, r_j / ‖ⁱz_j‖)) + π / K

(the camera's report ``ⁱz_j`` with the chance margin of Section 1d, σ_max the larger
std of Σ_MEAS; the known start poses with ``r_j = 0``; every bearing when
``‖ⁱz_j‖ ≤ r_j``), and the rows and the look before the leap use ``c_k + f_k`` for the
bearings out of view. The pair then closes by at most ``2 (B − f) ≤ 2 B − (D_s − d_0)``
from ``d_0``, to ``D_s − 2 B`` as from D_s. ``f_k`` is set for the bearings in view
every step (and raised, never lowered, for those out of view that a detection's cone
reaches); the bearings in view get no row from it, so it changes nothing while the
robot looks (nor ever with a 360° camera). Measured with it (the filter, 2000
particles): that episode and the other three collisions of the harsh sweep keep their
1.1 m spacing, and the whole sweep (324 episodes) reruns with 0 collisions, as does the
same sweep on new seeds; red team 9's packed 45° pair (Section 2c) keeps clear even
with its last-seen point released. In the default env, N = 6, β = 120°, seeds
0-19: pfcbf behind the filter 0.9954 final η and 9.50 s to the normalised threshold
(0.9954, 9.49 s without), the shipped learned policy 0.9963 and 15.72 s (0.9968,
15.67 s); random actions are changed as often (60.9%).

3. Walls
========

The env projects positions onto ``[r, L − r]²``: pushed into a wall a robot slides
along it, with a velocity nobody approved. With the robot's own world pose (its cue),
per wall with outward world normal e and clearance ``w`` to the projection line:

    (Rᵀ(θ) e) · v ≤ γ_w (w − m_arc)

(``γ_w = wall_gain``, used as ``min(γ_w, 1/dt)``, :func:`barrier_gain`), so the commanded velocity is the one the robot gets.

Parameters are :class:`~fov_marl.control.params.ControllerParams` fields
(``safety_model``, ``safety_risk``, ``safety_gain``, ``responsibility``,
``blind_bins``, ``blind_risk``, ``blind_speed_mps``, ``walls``, ``wall_gain``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import ndtri

from fov_marl.config import ScenarioConfig
from fov_marl.control.params import ControllerParams
from fov_marl.geometry import body_to_world, in_fov, integrate_unicycle, wrap_angle
from fov_marl.infos import SAFETY_CAUSES
from fov_marl.validation import describe

__all__ = [
    "ROW_NEIGHBOUR",
    "ROW_BLIND",
    "ROW_WALL",
    "ROW_CONE",
    "ROW_DENSITY",
    "ROW_LAST_SEEN",
    "ROW_BUDGET",
    "ROW_KIND_NAMES",
    "SafetyRows",
    "violated_kind_bits",
    "arc_margin",
    "arc_yaw_guard",
    "barrier_gain",
    "risk_quantile",
    "neighbour_halfplanes",
    "particle_halfplane_offsets",
    "bearing_cone",
    "blind_representatives",
    "wall_clearances",
    "blind_density_rows",
    "last_seen_rows",
    "detection_rows",
    "detection_sector_rows",
    "blind_travel_step",
    "blind_travel_reset",
    "bearing_angles_body",
    "bearing_travel_step",
    "bearing_travel_reset",
    "bearings_in_view",
    "bearing_travel_rows",
    "bearing_travel_floor",
    "reach_clear",
    "hold_band",
    "neighbour_row_offsets",
    "safety_rows",
    "team_safety_rows",
    "safety_triple",
    "invalid_rows",
]

#: masses within this of ``risk`` count as not exceeding it (the group sums are
#: differences of one running sum; ties must not depend on its round-off)
_MASS_TOL = 1e-9
#: ``SafetyRows.kind`` codes: the rows of a neighbour's line (Section 1, and the
#: camera's report, 1d), the particles' blind rows (2), the walls (3), the bearing cone
#: of a neighbour within D_s (1b), the Gaussian fits' density rows (2b), the last-seen
#: points (2c) and the blind travel budget (2d-2e). Every kind but the walls and cones
#: is a possible turn target of the safe fallback; otherwise the controllers treat all
#: kinds alike (the codes only say where a row comes from).
ROW_NEIGHBOUR, ROW_BLIND, ROW_WALL, ROW_CONE, ROW_DENSITY, ROW_LAST_SEEN, ROW_BUDGET = range(7)
#: ``ROW_KIND_NAMES[kind]``: the name of each code, the first seven intervention causes
#: of :data:`fov_marl.infos.SAFETY_CAUSES` (bit ``kind``; one list, defined there).
ROW_KIND_NAMES: tuple[str, ...] = SAFETY_CAUSES[: ROW_BUDGET + 1]


def safety_triple(safety: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``safety=`` argument of the controllers, ``(A, b, kind)``, as three real
    arrays (shapes are checked by the caller); anything else is a ``ValueError``."""
    if isinstance(safety, SafetyRows):
        return safety.A, safety.b, safety.kind
    if not isinstance(safety, tuple | list) or len(safety) != 3:
        raise ValueError(
            f"safety must be a SafetyRows or a tuple (A, b, kind), got {describe(safety)}"
        )
    out = []
    for name, x in zip(("A", "b", "kind"), safety, strict=True):
        a = np.asarray(x)
        if a.dtype == object or a.dtype.kind not in "biuf":
            raise ValueError(f"safety {name} must be a real array, got {describe(x)}")
        out.append(a)
    return out[0], out[1], out[2]


def invalid_rows(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(..., K)`` bool: rows ``A u + b ≥ 0`` that are not valid input, i.e. with a
    non-finite coefficient, ``b`` NaN or ``b = −∞`` (``b = +∞`` is a row that never
    binds, valid). The controllers give such a robot the invalid-input fallback (u = 0)
    instead of dropping the row."""
    A = np.asarray(A, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return ~np.isfinite(A).all(axis=-1) | np.isnan(b) | (b == -np.inf)


def barrier_gain(gain_per_s: float, dt_s: float) -> float:
    """The gain the rows use: ``min(γ, 1/dt)`` (1/s).

    The discrete-time barrier ``h_{k+1} ≥ (1 − γ dt) h_k`` (Section 1) needs ``γ dt ≤ 1``:
    beyond it the bound lets ``h`` change sign in one step, i.e. cross ``D_s`` (or the
    wall's clearance). ``γ dt = 1`` already allows reaching the boundary in one step, so
    a larger gain is used as ``1/dt``: the controller's defaults (2.5 1/s, chosen at
    dt = 0.2 s) stay valid at every dt the env accepts (up to 5 s).
    """
    return min(float(gain_per_s), 1.0 / float(dt_s))


def arc_margin(v_max: float, omega_max: float, dt: float) -> float:
    """Largest distance between the exact unicycle displacement and ``v dt`` (m).

    Over one step with constant body input the displacement in the start frame is
    ``M(φ) v dt``, ``M = [[sin φ/φ, −(1 − cos φ)/φ], [(1 − cos φ)/φ, sin φ/φ]]``,
    φ = ω dt (:func:`fov_marl.geometry.integrate_unicycle`). ``M − I`` is a scaled
    rotation, so ``‖(M − I) v dt‖ = |e^{iφ} − 1 − iφ| / φ · ‖v‖ dt``, largest at
    ``|φ| = ω_max dt`` and ``‖v‖ = v_max``.
    """
    phi = omega_max * dt
    if phi < 1e-9:
        return 0.0
    dev = abs(complex(math.cos(phi) - 1.0, math.sin(phi) - phi)) / phi
    return float(dev * v_max * dt)


def arc_yaw_guard(
    u: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    kind: np.ndarray,
    keep: np.ndarray,
    dt: float,
    eps_mps: float = 1e-6,
    stop_weight: float | None = None,
) -> np.ndarray:
    """Section 1c: the yaw rate limited so the step's arc approaches no held line.

    Args:
        u: ``(F, 3)`` body inputs ``[vx, vy, ω]`` (m/s, rad/s).
        A, b: ``(F, K, 3)``, ``(F, K)`` collision rows ``A u + b ≥ 0`` (raw or
            normalised: any positive scale per row), ``A = [−n s, 0]``.
        kind: ``(F, K)`` row kinds; keep: ``(F, K)`` bool, the rows that exist.
        dt: the step (s). eps_mps: the tolerance ε (m/s).
        stop_weight: λ of the QP metric ``‖Δv‖² + λ² Δω²`` (m/rad), or None. Where ω
            would be clipped, every kept row holds at standstill (``A (0, 0, ω) + b ≥ 0``)
            and ``‖v‖² < λ² (ω − ω_clipped)²``, the input ``(0, 0, ω)`` is returned
            instead: the robot stops translating and keeps its turn (no translation
            approaches nothing, whatever the arc). None: always clip.

    Returns:
        ``(F, 3)``: ``u`` with ω clipped to the interval (containing 0) where, for every
        neighbour, blind or cone row with ``b ≤ 0``, ``a cos(φ/2) + q sin(φ/2) ≤
        max(a, 0) + ε`` (``a = n · v``, ``q = n · J v``, φ = ω dt); translation unchanged
        (or, with ``stop_weight``, the translation dropped and ω unchanged).
    """
    u = np.array(u, dtype=np.float64, copy=True)
    A = np.asarray(A, dtype=np.float64)
    on = (
        np.asarray(keep, dtype=bool)
        & (np.asarray(b) <= 0.0)
        & (np.asarray(kind) != ROW_WALL)
        & (np.asarray(kind) >= 0)
    )
    if u.shape[0] == 0 or not on.any():
        return u
    nn = np.hypot(A[..., 0], A[..., 1])
    on &= nn > 0.0
    safe = np.where(on, nn, 1.0)
    nx, ny = -A[..., 0] / safe, -A[..., 1] / safe
    vx, vy = u[:, None, 0], u[:, None, 1]
    a = nx * vx + ny * vy
    q = ny * vx - nx * vy  # n · J v, J v = (−v_y, v_x)
    c = np.maximum(a, 0.0) + eps_mps
    rho = np.hypot(a, q)
    bind = on & (rho > c)
    th0 = np.arctan2(q, a)
    half = np.arccos(np.clip(c / np.where(bind, rho, 1.0), -1.0, 1.0))
    hi = np.where(bind & (q > 0.0), np.maximum(th0 - half, 0.0), np.inf).min(axis=1)
    lo = np.where(bind & (q < 0.0), np.minimum(th0 + half, 0.0), -np.inf).max(axis=1)
    w_in = u[:, 2].copy()
    u[:, 2] = np.clip(w_in, 2.0 * lo / dt, 2.0 * hi / dt)
    if stop_weight is None:
        return u
    slowed = u[:, 2] != w_in
    if not slowed.any():
        return u
    # the turn in place (0, 0, ω): allowed where every kept row holds at standstill
    at_rest = A[..., 2] * w_in[:, None] + np.asarray(b, dtype=np.float64)
    holds = np.where(np.asarray(keep, dtype=bool), at_rest >= 0.0, True).all(axis=1)
    cost_stop = u[:, 0] ** 2 + u[:, 1] ** 2
    stop = slowed & holds & (cost_stop < (stop_weight * (w_in - u[:, 2])) ** 2)
    u[stop, :2] = 0.0
    u[stop, 2] = w_in[stop]
    return u


def risk_quantile(risk: float) -> float:
    """``z = Φ⁻¹(1 − δ)``: the one-sided Gaussian quantile of the neighbour rows."""
    return float(ndtri(1.0 - risk))


@dataclass(frozen=True)
class SafetyRows:
    """Rows ``A u + b ≥ 0`` of every robot, padded to a common count ``K``.

    Attributes:
        A: ``(R, K, 3)`` (dimensionless: ``[−n_x, −n_y, 0]``).
        b: ``(R, K)`` speed bounds (m/s); +inf for padding rows.
        kind: ``(R, K)`` int8, where each row comes from: :data:`ROW_NEIGHBOUR` /
            :data:`ROW_BLIND` / :data:`ROW_WALL` / :data:`ROW_CONE` (the bearing cone of
            a neighbour row, Section 1b) / :data:`ROW_DENSITY` / :data:`ROW_LAST_SEEN` /
            :data:`ROW_BUDGET` (names: :data:`ROW_KIND_NAMES`), −1 for padding.
        h: ``(R, K)`` barrier value of each row (m): clearance minus D_s (neighbour,
            blind) or wall clearance; +inf for padding.
    """

    A: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    h: np.ndarray

    def robot(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(A (K_k, 3), b (K_k,), kind (K_k,))`` of robot k without padding rows."""
        keep = self.kind[k] >= 0
        return self.A[k][keep], self.b[k][keep], self.kind[k][keep]


def violated_kind_bits(rows: SafetyRows, u: np.ndarray, tol_mps: float = 1e-9) -> np.ndarray:
    """Which kinds of row an input violates: bit ``k`` set where ``u`` breaks a row of
    kind ``k`` (``A u + b < −tol``; padding rows never count).

    The filter's report of why it changed an action (``safety/cause_bits``,
    :data:`fov_marl.infos.SAFETY_CAUSES`) reads it on the policy's input u*.

    Args:
        rows: the robots' rows (``R`` robots, ``K`` rows).
        u: ``(R, 3)`` body-frame inputs ``[vx m/s, vy m/s, ω rad/s]``.
        tol_mps: how far (m/s) a row may be broken before it counts.

    Returns:
        ``(R,)`` int64 bit masks (``1 << kind`` per violated kind).
    """
    u = np.asarray(u, dtype=np.float64)
    kind = np.asarray(rows.kind)
    if kind.shape[1] == 0:
        return np.zeros(kind.shape[0], dtype=np.int64)
    with np.errstate(invalid="ignore"):
        slack = np.einsum("rkc,rc->rk", rows.A, u) + rows.b
    bad = (slack < -tol_mps) & (kind >= 0)
    bits = np.where(bad, np.left_shift(np.int64(1), np.maximum(kind, 0).astype(np.int64)), 0)
    return np.bitwise_or.reduce(bits, axis=1)


def neighbour_halfplanes(
    mean_body: np.ndarray, cov_body: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Separating lines of Section 1 of the module docstring.

    Args:
        mean_body: ``(R, M, 2)`` ⁱμ_j (m).
        cov_body: ``(R, M, 2, 2)`` ⁱΣ_j (m²); zeros for exact positions.
        z: the one-sided quantile (:func:`risk_quantile`).

    Returns:
        ``(n (R, M, 2) unit lines of sight, s (R, M) m)``: j lies beyond ``n·q = s``
        with probability ``Φ(z)``. A mean at the origin gets n = (1, 0), s = −z σ.
    """
    mu = np.asarray(mean_body, dtype=np.float64)
    S = np.asarray(cov_body, dtype=np.float64)
    r = np.hypot(mu[..., 0], mu[..., 1])
    safe_r = np.where(r > 1e-9, r, 1.0)
    nx = np.where(r > 1e-9, mu[..., 0] / safe_r, 1.0)
    ny = np.where(r > 1e-9, mu[..., 1] / safe_r, 0.0)
    var = S[..., 0, 0] * nx * nx + 2.0 * S[..., 0, 1] * nx * ny + S[..., 1, 1] * ny * ny
    s = r - z * np.sqrt(np.maximum(var, 0.0))
    return np.stack([nx, ny], -1), s


def bearing_cone(
    mean_body: np.ndarray, cov_body: np.ndarray, h: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Half-angle of the cone of bearings a neighbour may lie at (Section 1b).

    Args:
        mean_body: ``(R, M, 2)`` ⁱμ_j (m).
        cov_body: ``(R, M, 2, 2)`` ⁱΣ_j (m²).
        h: ``(R, M)`` the rows' barrier values (m); the cone applies where ``h < 0``.
        z: the one-sided quantile (:func:`risk_quantile`).

    Returns:
        ``(sin α (R, M) in [0, 1], inside (R, M) bool)``: ``sin α = min(1, z σ_t / ‖μ‖)``
        with ``σ_t`` the std of j's position across the line of sight; ``inside``:
        ``h < 0`` and ``‖μ‖ > 0``.
    """
    mu = np.asarray(mean_body, dtype=np.float64)
    S = np.asarray(cov_body, dtype=np.float64)
    r = np.hypot(mu[..., 0], mu[..., 1])
    ok = r > 1e-9
    safe_r = np.where(ok, r, 1.0)
    tx, ty = -mu[..., 1] / safe_r, mu[..., 0] / safe_r
    var_t = S[..., 0, 0] * tx * tx + 2.0 * S[..., 0, 1] * tx * ty + S[..., 1, 1] * ty * ty
    sin_a = np.minimum(1.0, z * np.sqrt(np.maximum(var_t, 0.0)) / safe_r)
    return np.where(ok, sin_a, 0.0), ok & (np.asarray(h) < 0.0)


def _cone_rows(
    mean_body: np.ndarray,
    cov_body: np.ndarray,
    n: np.ndarray,
    b: np.ndarray,
    h: np.ndarray,
    max_rad: float,
    risk: float,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """The two edge rows of the cone of bearings (Sections 1b and 1d) where ``h < 0``.

    Args:
        mean_body, cov_body: ``(R, M, 2)``, ``(R, M, 2, 2)`` the Gaussian the cone is
            drawn around (the posterior, or the detection with Σ_MEAS), in Σ_i.
        n: ``(R, M, 2)`` its unit lines of sight. b: ``(R, M)`` the row's offset (m/s),
            which the edges take over. h: ``(R, M)`` the row's barrier value (m); +inf,
            or ≥ 0, where there is no cone.
        max_rad: the cap on the half-angle α. risk: δ.

    Returns:
        Two ``(A (R, M, 3), b (R, M), kind (R, M) int8, h (R, M))`` blocks of
        :class:`SafetyRows`, ``n_± = cos α n ± sin α t`` (b, h = +inf and kind = −1
        where there is no cone).
    """
    sin_a, inside = bearing_cone(mean_body, cov_body, h, risk_quantile(risk))
    sin_a = np.minimum(sin_a, math.sin(max_rad))
    cos_a = np.sqrt(1.0 - sin_a * sin_a)
    t = np.stack([-n[..., 1], n[..., 0]], -1)
    out = []
    for sign in (1.0, -1.0):
        A = np.zeros(n.shape[:-1] + (3,))
        A[..., 0:2] = -(cos_a[..., None] * n + sign * sin_a[..., None] * t)
        out.append(
            (
                A,
                np.where(inside, b, np.inf),
                np.where(inside, ROW_CONE, -1).astype(np.int8),
                np.where(inside, h, np.inf),
            )
        )
    return out


def particle_halfplane_offsets(
    p_body: np.ndarray, counts: np.ndarray, n_body: np.ndarray, risk: float
) -> np.ndarray:
    """The particles' own δ-quantile along each line of sight (Section 1, ``"particles"``).

    For neighbour j of robot i with ``P_j`` particles (equal weights, as after each
    resampling) and line of sight ``n``, ``s_j`` is the ``(⌊δ P_j⌋ + 1)``-th smallest
    projection ``n · p`` of j's particles, so at most a fraction δ of them lies on the
    near side of the line ``n · q = s_j``: the chance constraint of Section 1 on the
    belief itself instead of on its Gaussian fit.

    Args:
        p_body: ``(R, P, 2)`` particles in Σ_i (m), each row sorted by owner in
            neighbour-column order (:meth:`VectorTrackerBank.particles_all`).
        counts: ``(R, M)`` particles per neighbour column; rows sum to P.
        n_body: ``(R, M, 2)`` unit lines of sight.
        risk: δ in (0, 0.5).

    Returns:
        ``(R, M)`` offsets ``s_j`` (m); −inf for a neighbour without particles.
    """
    p = np.asarray(p_body, dtype=np.float64)
    c = np.asarray(counts, dtype=np.int64)
    n = np.asarray(n_body, dtype=np.float64)
    R, P = p.shape[:2]
    M = c.shape[1]
    out = np.full((R, M), -np.inf)
    if R == 0 or M == 0 or P == 0:
        return out
    g = np.repeat(np.arange(R * M), c.reshape(-1))  # (R P,) group = (robot, column)
    nn = n.reshape(-1, 2)[g]
    proj = p.reshape(-1, 2)[:, 0] * nn[:, 0] + p.reshape(-1, 2)[:, 1] * nn[:, 1]
    order = np.lexsort((proj, g))
    sorted_proj = proj[order]
    flat_c = c.reshape(-1)
    start = np.concatenate([[0], np.cumsum(flat_c)[:-1]])
    k = np.minimum(np.floor(risk * flat_c).astype(np.int64), np.maximum(flat_c - 1, 0))
    has = flat_c > 0
    out.reshape(-1)[has] = sorted_proj[(start + k)[has]]
    return out


def blind_representatives(
    p_body: np.ndarray,
    mass: np.ndarray,
    n_bins: int,
    risk: float,
    r_cut: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Per bearing sector, the first particle at which the expected count exceeds ``risk``.

    Args:
        p_body: ``(R, P, 2)`` particle positions in Σ_i (m).
        mass: ``(R, P)`` expected-neighbour mass of each particle (``1/P_j``; 0 for
            particles to ignore, e.g. of detected neighbours).
        n_bins: K ≥ 1 sectors of width 2π/K, sector 0 starting at bearing −π.
        risk: δ_b ≥ 0, expected neighbours tolerated closer than the representative.
        r_cut: particles farther than this (m) are ignored (their rows would be pruned).

    Returns:
        ``(rep (R, K, 2) m, found (R, K) bool)``; ``rep`` is 0 where not found.
    """
    p = np.asarray(p_body, dtype=np.float64)
    w = np.asarray(mass, dtype=np.float64)
    R = p.shape[0]
    rep = np.zeros((R, n_bins, 2))
    found = np.zeros((R, n_bins), dtype=bool)
    # the particles with hypot(x, y) < r_cut, in row-major order: a cheap superset by the
    # squared range first (its rounding is far inside the 1e-9 margin), then hypot on
    # that superset only (the same particles and ranges as hypot over all of them)
    x, y = p[..., 0], p[..., 1]
    d2 = x * x
    d2 += y * y
    rows, cols = np.nonzero((d2 < (r_cut * r_cut) * (1.0 + 1e-9)) & (w > 0.0))
    rr = np.hypot(x[rows, cols], y[rows, cols])
    near = rr < r_cut
    rows, cols, rr = rows[near], cols[near], rr[near]
    if rows.size == 0:
        return rep, found
    ang = np.arctan2(p[rows, cols, 1], p[rows, cols, 0])
    k = np.minimum((ang + math.pi) * (n_bins / (2.0 * math.pi)), n_bins - 1).astype(np.int64)
    g = rows * n_bins + k  # group = (robot, sector)
    order = np.lexsort((rr, g))
    g, rows, cols, m = g[order], rows[order], cols[order], w[rows[order], cols[order]]
    cum = np.cumsum(m)
    start = np.ones(g.size, dtype=bool)
    start[1:] = g[1:] != g[:-1]
    base = np.maximum.accumulate(np.where(start, cum - m, 0.0))
    exceed = cum - base > risk + _MASS_TOL
    prev = np.zeros(g.size, dtype=bool)
    prev[1:] = exceed[:-1] & ~start[1:]
    first = exceed & ~prev
    gi = g[first]
    rep.reshape(-1, 2)[gi] = p[rows[first], cols[first]]
    found.reshape(-1)[gi] = True
    return rep, found


def blind_density_rows(
    mean_body: np.ndarray,
    cov_body: np.ndarray,
    detected: np.ndarray,
    n_bins: int,
    risk: float,
    r_cut: float,
    fov_rad: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blind rows from the Gaussian fits where the particles are too sparse (Section 2b).

    For every bearing sector k outside the camera sector (centre θ_k with
    ``|θ_k| > β/2 − π/K``) the expected number of undetected neighbours in the sector's
    disk slice of radius ``r_cut`` is approximated by ``Σ_j N(c_k; μ_j, Σ_j) π r_cut² / K``
    with ``c_k`` the slice's mid-point at ``r_cut / 2``. Where it exceeds ``risk`` the row
    ``n_k · v ≤ 0`` forbids approaching that sector.

    Returns:
        ``(A (R, K, 3), b (R, K) m/s (+inf where no row), h (R, K) m)``.
    """
    mu = np.asarray(mean_body, dtype=np.float64)
    S = np.asarray(cov_body, dtype=np.float64)
    R = mu.shape[0]
    th = -math.pi + (np.arange(n_bins) + 0.5) * (2.0 * math.pi / n_bins)
    c = 0.5 * r_cut * np.stack([np.cos(th), np.sin(th)], -1)  # (K, 2)
    a, bb, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    det = np.maximum(a * d - bb * bb, 1e-12)
    dx = c[None, None, :, 0] - mu[..., None, 0]  # (R, M, K)
    dy = c[None, None, :, 1] - mu[..., None, 1]
    q = (d[..., None] * dx * dx - 2.0 * bb[..., None] * dx * dy + a[..., None] * dy * dy) / det[
        ..., None
    ]
    pdf = np.exp(-0.5 * q) / (2.0 * math.pi * np.sqrt(det))[..., None]
    pdf = np.where(detected[..., None], 0.0, pdf)
    count = pdf.sum(axis=1) * (math.pi * r_cut * r_cut / n_bins)  # (R, K)
    visible = np.abs(th) <= 0.5 * fov_rad - math.pi / n_bins
    on = (count > risk) & ~visible[None, :]
    A = np.zeros((R, n_bins, 3))
    A[..., 0] = -np.cos(th)[None, :]
    A[..., 1] = -np.sin(th)[None, :]
    b = np.where(on, 0.0, np.inf)
    return A, b, np.where(on, 0.0, np.inf)


def last_seen_rows(
    last_seen_body: np.ndarray,
    age_s: np.ndarray,
    detected: np.ndarray,
    *,
    radius_m: float,
    reach_sigma_m: float,
    v_max_mps: float,
    fov_rad: float,
    detection_range_m: float,
    max_age_s: float = math.inf,
    release: str = "point",
) -> tuple[np.ndarray, np.ndarray]:
    """Rows towards lost neighbours' last-seen points (Section 2c of the module docstring).

    Args:
        last_seen_body: ``(R, M, 2)`` last-seen point of each neighbour in Σ_i (m);
            NaN where the neighbour was never seen.
        age_s: ``(R, M)`` τ, seconds since that detection.
        detected: ``(R, M)`` bool, neighbour in the last observation (no row).
        radius_m: rows only for points nearer than this (m).
        reach_sigma_m: ``z σ_meas`` (m), the uncertainty of the last detection.
        v_max_mps: the neighbour's top speed (m/s).
        fov_rad, detection_range_m: the camera (a point it sees is released).
        max_age_s: a point older than this (s) is released.
        release: ``"point"``: a point inside the camera's view is released; ``"disk"``:
            only when its whole disk of radius ``reach_sigma_m`` (the last detection's
            uncertainty) lies inside the view's sector and range.

    Returns:
        ``(n (R, M, 2) unit directions, h (R, M) m)`` with ``h = +inf`` where there is
        no row; ``h`` is the clearance beyond the reach disk minus nothing else (the
        caller subtracts D_s and the arc margin).
    """
    c = np.asarray(last_seen_body, dtype=np.float64)
    r = np.hypot(c[..., 0], c[..., 1])
    valid = np.isfinite(r) & ~np.asarray(detected, dtype=bool) & (r < radius_m) & (r > 1e-9)
    bearing = np.arctan2(c[..., 1], c[..., 0])
    if release == "disk":  # the point's uncertainty, not the point, must be in view
        half = np.arcsin(np.minimum(1.0, reach_sigma_m / np.where(r > 1e-9, r, 1.0)))
        in_view = (np.abs(bearing) + half <= 0.5 * fov_rad) & (
            r + reach_sigma_m <= detection_range_m
        )
    elif release == "point":
        in_view = (np.abs(bearing) <= 0.5 * fov_rad) & (r <= detection_range_m)
    else:
        raise ValueError(f"release must be 'point' or 'disk', got {release!r}")
    on = valid & ~in_view & (np.asarray(age_s, dtype=np.float64) <= max_age_s)
    safe_r = np.where(on, r, 1.0)
    n = np.where(on[..., None], c / safe_r[..., None], 0.0)
    reach = reach_sigma_m + v_max_mps * np.asarray(age_s, dtype=np.float64)
    h = np.where(on, r - reach, np.inf)
    return n, h


def detection_rows(
    detection_body: np.ndarray, meas_cov_xy: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rows on the camera's own report of each detected neighbour (Section 1d).

    Args:
        detection_body: ``(R, M, 2)`` the last observation's detections ``ⁱz_j`` in Σ_i
            (m); NaN where the neighbour was not detected.
        meas_cov_xy: ``(2, 2)`` Σ_MEAS of the position (m²), the camera's noise.
        z: the one-sided quantile (:func:`risk_quantile`).

    Returns:
        ``(n (R, M, 2) unit lines of sight, s (R, M) m)`` as :func:`neighbour_halfplanes`
        gives for the detection taken as a Gaussian with covariance Σ_MEAS; ``s = +inf``
        (and ``n = 0``) where there is no detection or it lies at the robot's centre.
    """
    zb = np.asarray(detection_body, dtype=np.float64)
    r = np.hypot(zb[..., 0], zb[..., 1])
    on = np.isfinite(r) & (r > 1e-9)
    cov = np.broadcast_to(np.asarray(meas_cov_xy, dtype=np.float64), zb.shape + (2,))
    n, s = neighbour_halfplanes(np.where(on[..., None], zb, 1.0), cov, z)
    return np.where(on[..., None], n, 0.0), np.where(on, s, np.inf)


def detection_sector_rows(
    detection_body: np.ndarray, fov_rad: float, range_m: float, clip_xy_m: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the camera's report contradicts the camera (Section 1e): its sector's rows.

    The camera reports neighbour j only while j's *true* position lies in the sector F_i
    (``|bearing| ≤ β/2``, range ≤ R_d), and its noise is clipped per axis, so j lies in
    ``F_i ∩ box(ⁱz_j, clip)``. A report outside F_i (noise of the order of the range
    moves it there: measured, a neighbour 1.27 m ahead reported 1.05 m behind with
    0.71 m noise) gives a line of sight that may point away from j. For such a report
    this gives approach-only directions along the sector's edges and its axis,
    ``θ ∈ {−β/2, 0, +β/2}``: with β ≤ π the axis is implied by the edges and together
    they forbid approaching any bearing of F_i (the polar cone of the sector); with β > π
    the three span more than a half-plane and leave no translation towards anything.
    The clearance is the distance from the robot to the clip box, a lower bound on
    ``‖ⁱp_j‖``. With β ≥ 2π there is no bearing to contradict and no row.

    Args:
        detection_body: ``(R, M, 2)`` the last observation's detections in Σ_i (m, NaN:
            not detected).
        fov_rad: β. range_m: R_d.
        clip_xy_m: the noise clip per axis (m), ``meas_noise_clip_sigma`` σ_x, σ_y.

    Returns:
        ``(n (3, 2) unit directions, clear (R, M) m (+inf where the report is in F_i or
        absent), outside (R, M) bool)``; "in F_i" is the camera's own test
        (:func:`fov_marl.geometry.in_fov`).
    """
    zb = np.asarray(detection_body, dtype=np.float64)
    th = np.array([-0.5 * fov_rad, 0.0, 0.5 * fov_rad])
    n = np.stack([np.cos(th), np.sin(th)], -1)
    on = np.isfinite(zb).all(axis=-1)
    if fov_rad >= 2.0 * math.pi:
        return n, np.full(on.shape, np.inf), np.zeros(on.shape, dtype=bool)
    z = np.where(on[..., None], zb, 0.0)
    outside = on & ~in_fov(z, fov_rad, range_m)
    dx = np.maximum(np.abs(z[..., 0]) - clip_xy_m[0], 0.0)  # distance to the box
    dy = np.maximum(np.abs(z[..., 1]) - clip_xy_m[1], 0.0)
    clear = np.where(outside, np.hypot(dx, dy), np.inf)
    return n, clear, outside


def _approach_only_rows(
    n: np.ndarray, clear_m: np.ndarray, kind: int, d_s_m: float, m_arc_m: float, gain: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows that only take approach away (Sections 1d and 2c): ``n · v ≤ max(0, g h)``,
    ``h = clear − D_s − m_arc``, never a push.

    Args:
        n: ``(R, M, 2)`` unit directions in Σ_i. clear_m: ``(R, M)`` clearance along n (m);
            +inf where there is no row. kind: the rows' ``SafetyRows.kind`` code.
        d_s_m, m_arc_m: D_s and the arc margin (m). gain: ρ γ (1/s).

    Returns:
        ``(A (R, M, 3), b (R, M), kind (R, M) int8, h (R, M))`` blocks of :class:`SafetyRows`
        (b, h = +inf and kind = −1 where there is no row).
    """
    on = np.isfinite(clear_m)
    h = np.where(on, clear_m - d_s_m - m_arc_m, np.inf)
    A = np.zeros(n.shape[:-1] + (3,))
    A[..., 0:2] = -n
    b = np.where(on, np.maximum(0.0, gain * np.where(on, h, 0.0)), np.inf)
    return A, b, np.where(on, kind, -1).astype(np.int8), h


def blind_travel_step(
    e_world: np.ndarray,
    v_body: np.ndarray,
    yaw_rad: np.ndarray,
    dt_s: float,
    memory_s: float = math.inf,
) -> np.ndarray:
    """``e ← λ e + Δ`` (Section 2d of the module docstring), ``λ = exp(−dt / T)``.

    Args:
        e_world: ``(R, 2)`` net displacement since the robot last looked along it (m,
            world frame).
        v_body: ``(R, 2)`` applied body-frame translation velocity (m/s).
        yaw_rad: ``(R,)`` the robots' yaw when the input is applied.
        memory_s: T, the time constant of the leak (s); inf: no leak.

    Returns:
        ``(R, 2)`` the new ``e`` (m).
    """
    heading = np.zeros((len(yaw_rad), 3))
    heading[:, 2] = yaw_rad  # a displacement: rotate only
    d = body_to_world(np.asarray(v_body, dtype=np.float64) * dt_s, heading)
    lam = math.exp(-dt_s / memory_s) if math.isfinite(memory_s) else 1.0
    return lam * np.asarray(e_world, dtype=np.float64) + d


def blind_travel_reset(
    e_world: np.ndarray, yaw_rad: np.ndarray, fov_rad: float, margin_rad: float
) -> np.ndarray:
    """Zero ``e`` where its direction lies in the camera's view (within ``β/2 − margin``).
    A 360° camera has no edge: ``e`` is always zeroed (the margin would otherwise count
    travel straight backwards as blind and turn the robot round for nothing).

    Args:
        e_world: ``(R, 2)`` (m, world frame). yaw_rad: ``(R,)``.
        fov_rad: β. margin_rad: inward angular margin (rad).
    """
    e = np.asarray(e_world, dtype=np.float64)
    if fov_rad >= 2.0 * math.pi:
        return np.zeros_like(e)
    bearing = np.arctan2(e[:, 1], e[:, 0]) - np.asarray(yaw_rad, dtype=np.float64)
    bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
    seen = np.abs(bearing) <= 0.5 * fov_rad - margin_rad
    return np.where(seen[:, None], 0.0, e)


def _bearing_dirs_world(k: int) -> np.ndarray:
    """``(K, 2)`` the unit world directions of the K budget bearings, ``2π k / K``."""
    ang = 2.0 * math.pi * np.arange(k) / k
    return np.stack([np.cos(ang), np.sin(ang)], -1)


def bearing_travel_step(
    c_m: np.ndarray,
    v_body: np.ndarray,
    yaw_rad: np.ndarray,
    dt_s: float,
    memory_s: float = math.inf,
    floor_m: float = 0.0,
    omega_radps: np.ndarray | None = None,
) -> np.ndarray:
    """``c_k ← max(−F, λ c_k + n_k · Δ)`` (Section 2e of the module docstring; the
    pipeline's ``F`` is ``ControllerParams.blind_travel_credit_m``, default 0).

    Args:
        c_m: ``(R, K)`` approach made towards each world bearing ``n_k = (cos 2πk/K,
            sin 2πk/K)`` since the camera last looked at it (m).
        v_body: ``(R, 2)`` applied body-frame translation velocity (m/s).
        yaw_rad: ``(R,)`` the robots' yaw when the input is applied.
        memory_s: T, the time constant of the leak (s); inf: no leak.
        floor_m: F ≥ 0, the most credit moving away from a bearing builds towards it (m).
        omega_radps: ``(R,)`` the applied yaw rates: Δ is the step's exact arc
            (:func:`fov_marl.geometry.integrate_unicycle`); None: the straight ``v dt``.

    Returns:
        ``(R, K)`` the new ``c`` (m), ``≥ −F``.
    """
    c = np.asarray(c_m, dtype=np.float64)
    start = np.zeros((len(yaw_rad), 3))
    start[:, 2] = yaw_rad
    v = np.asarray(v_body, dtype=np.float64)
    w = np.zeros(len(yaw_rad)) if omega_radps is None else np.asarray(omega_radps, np.float64)
    d = integrate_unicycle(start, v, w, dt_s)[:, :2]
    lam = math.exp(-dt_s / memory_s) if math.isfinite(memory_s) else 1.0
    return np.maximum(-floor_m, lam * c + d @ _bearing_dirs_world(c.shape[1]).T)


def bearing_angles_body(k: int, yaw_rad: np.ndarray) -> np.ndarray:
    """``(R, K)`` the budget bearings in each Σ_i, wrapped to ``(−π, π]``."""
    ang = 2.0 * math.pi * np.arange(k)[None, :] / k - np.asarray(yaw_rad, np.float64)[:, None]
    return (ang + math.pi) % (2.0 * math.pi) - math.pi


def bearings_in_view(ang_body_rad: np.ndarray, fov_rad: float, margin_rad: float) -> np.ndarray:
    """Bearings (``ang_body_rad``, in Σ_i) within ``β/2 − margin`` of the camera axis,
    1e-9 rad of round-off included: a bin whose sector ends on the view's edge is in
    view. The one view test of the blind travel budgets (reset and rows)."""
    return np.abs(ang_body_rad) <= 0.5 * fov_rad - margin_rad + 1e-9


def bearing_travel_reset(
    c_m: np.ndarray, yaw_rad: np.ndarray, fov_rad: float, margin_rad: float
) -> np.ndarray:
    """Zero ``c_k`` for the bearings in the camera's view (within ``β/2 − margin``, 1e-9
    rad of round-off included: a bin whose sector ends on the view's edge is in view).
    A 360° camera has no edge: every bearing is in view (the margin would otherwise leave
    the bins within ``margin`` of straight behind unseen for good).

    Args:
        c_m: ``(R, K)`` (m). yaw_rad: ``(R,)``. fov_rad: β. margin_rad: inward margin.
    """
    c = np.asarray(c_m, dtype=np.float64)
    if fov_rad >= 2.0 * math.pi:
        return np.zeros_like(c)
    seen = bearings_in_view(bearing_angles_body(c.shape[1], yaw_rad), fov_rad, margin_rad)
    return np.where(seen, 0.0, c)


def bearing_travel_rows(
    c_m: np.ndarray,
    yaw_rad: np.ndarray,
    budget_m: float | np.ndarray,
    dt_s: float,
    v_max_mps: float,
    fov_rad: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows ``n_k · v ≤ max(0, (B − c_k) / dt)`` of the bearings where they can bind.

    A row binds where one step at full speed could spend the rest of the budget,
    ``B − c_k < v_max dt``. With ``fov_rad`` (β) that includes the bearings outside the
    view with ``c_k = 0`` (never approached, or approached and left): when
    ``v_max dt > B`` (e.g. v_max = 5 m/s at dt = 0.2 s, or dt = 1 s at 1 m/s) one step
    could otherwise carry the robot ``v_max dt`` towards a bearing it has not looked at,
    past the budget (red team 5 measured 0.99 m blind in one step with B = 0.5 m). The
    bearings in view (within ``β/2 − π/K``, as :func:`bearing_travel_reset` clears them)
    get no such row. Without ``fov_rad`` only ``c_k > 0`` rows are written (the rule
    before; the same rows whenever ``v_max dt ≤ B``, the defaults' case).

    Args:
        c_m: ``(R, K)`` the approach per world bearing (m). yaw_rad: ``(R,)``.
        budget_m: B (m), or ``(R, 1)`` per robot. dt_s: the step (s). v_max_mps: the
            speed limit (m/s). fov_rad: the camera amplitude β (rad), or None.

    Returns:
        ``(A (R, K, 3), b (R, K) m/s, h (R, K) m)``: ``A = [−n_k, 0]`` in Σ_i,
        ``h = B − c_k``; ``b = h = +inf`` where no row binds.
    """
    c = np.asarray(c_m, dtype=np.float64)
    R, K = c.shape
    ang = bearing_angles_body(K, yaw_rad)
    left = budget_m - c
    watched = c > 0.0
    if fov_rad is not None and fov_rad < 2.0 * math.pi:
        watched = watched | ~bearings_in_view(ang, fov_rad, math.pi / K)
    on = watched & (left < v_max_mps * dt_s)
    A = np.zeros((R, K, 3))
    A[..., 0] = -np.cos(ang)
    A[..., 1] = -np.sin(ang)
    b = np.where(on, np.maximum(0.0, left / dt_s), np.inf)
    return A, b, np.where(on, left, np.inf)


def bearing_travel_floor(
    near_body: np.ndarray,
    slack_m: np.ndarray,
    yaw_rad: np.ndarray,
    k: int,
    safety_distance_m: float,
    budget_m: float,
) -> np.ndarray:
    """The part of each bearing's budget the neighbours seen now have used (Section 2g).

    Args:
        near_body: ``(R, M, 2)`` where the neighbours are reported now in Σ_i (m): the
            camera's detections, or the known start poses; NaN: none.
        slack_m: ``(R, M)`` (or broadcastable) how much nearer than reported each may be
            (m): ``z_δ σ_max`` for a detection, 0 for a known pose.
        yaw_rad: ``(R,)`` the robots' yaw. k: K_b, the world bearings of the budget.
        safety_distance_m: D_s. budget_m: B.

    Returns:
        ``(R, K)`` ``f_k = max_j clip((D_s − d_j) / 2, 0, B)`` over the neighbours whose
        cone of bearings, widened by half a bin, holds bearing k (0 where none does).
    """
    p = np.asarray(near_body, dtype=np.float64)
    R, M = p.shape[:2]
    if M == 0:
        return np.zeros((R, k))
    slack = np.broadcast_to(np.asarray(slack_m, dtype=np.float64), (R, M))
    dist = np.hypot(p[..., 0], p[..., 1])
    on = np.isfinite(dist)
    used = np.where(on, np.clip(0.5 * (safety_distance_m - (dist - slack)), 0.0, budget_m), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):  # NaN rows: used = 0 above
        half = np.where(dist > slack, np.arcsin(np.clip(slack / dist, 0.0, 1.0)), math.pi)
    psi = np.arctan2(p[..., 1], p[..., 0])  # (R, M), NaN where none
    off = np.abs(wrap_angle(bearing_angles_body(k, yaw_rad)[:, None, :] - psi[..., None]))
    hit = off <= half[..., None] + math.pi / k + 1e-9  # False where psi is NaN
    return np.max(np.where(hit, used[..., None], 0.0), axis=1)


def reach_clear(centre_body: np.ndarray, radius_m: np.ndarray, horizon_m: float) -> np.ndarray:
    """The robots no neighbour can be near (Section 2f): every reachable disk's edge is
    farther than ``horizon_m``.

    Args:
        centre_body: ``(R, M, 2)`` centres of the neighbours' reachable disks in Σ_i (m);
            NaN: never detected (the neighbour may be anywhere).
        radius_m: ``(R, M)`` their radii (m).
        horizon_m: H (m).

    Returns:
        ``(R,)`` bool, True where ``‖c_j‖ − r_j > H`` for every neighbour j (and for a
        robot without neighbours).
    """
    c = np.asarray(centre_body, dtype=np.float64)
    r = np.asarray(radius_m, dtype=np.float64)
    gap = np.hypot(c[..., 0], c[..., 1]) - r  # NaN for a never-detected neighbour
    return np.all(gap > horizon_m, axis=1)  # NaN > H is False


def wall_clearances(
    pose_world: np.ndarray, arena_size_m: float, robot_radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Outward wall normals in Σ_i and clearances to the env's projection lines.

    Args:
        pose_world: ``(R, 3)`` own world poses ``[x m, y m, yaw rad]``.

    Returns:
        ``(n_body (R, 4, 2), w (R, 4) m)`` for the walls x = r, x = L − r, y = r,
        y = L − r (outward normals −e_x, +e_x, −e_y, +e_y).
    """
    pose = np.asarray(pose_world, dtype=np.float64)
    lo, hi = robot_radius_m, arena_size_m - robot_radius_m
    x, y, th = pose[:, 0], pose[:, 1], pose[:, 2]
    w = np.stack([x - lo, hi - x, y - lo, hi - y], -1)
    e = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    # Rᵀ(θ) e: world → body
    nbx = c * e[None, :, 0] + s * e[None, :, 1]
    nby = -s * e[None, :, 0] + c * e[None, :, 1]
    return np.stack([nbx, nby], -1), w


def team_safety_rows(
    config: ScenarioConfig,
    params: ControllerParams,
    *,
    mean_body: np.ndarray,
    cov_body: np.ndarray,
    detected: np.ndarray,
    velocity_est_body: np.ndarray | None = None,
    pose_world: np.ndarray | None = None,
    particles_body: np.ndarray | None = None,
    particle_mass: np.ndarray | None = None,
    fov_rad: float | None = None,
    blind: bool = True,
    last_seen_body: np.ndarray | None = None,
    last_seen_age_s: np.ndarray | None = None,
    blind_travel_body: np.ndarray | None = None,
    particle_counts: np.ndarray | None = None,
    bearing_travel_m: np.ndarray | None = None,
    detection_body: np.ndarray | None = None,
) -> SafetyRows:
    """:func:`safety_rows` with the scenario's quantities and the controller's knobs.

    Args:
        config: the scenario (D_s, v_max, ω_max, dt, arena, robot radius, β).
        params: the controller parameters (the ``safety_*``, ``blind_*``, ``wall*`` and
            ``responsibility`` fields).
        fov_rad: β for the density blind rows (default ``config.fov_rad``; 2π: none).
        blind: False leaves out the blind rows (no particles, no density, no
            last-seen rows, no travel budget).
        bearing_travel_m: ``(R, K_b)`` the approach per budget bearing (Section 2e),
            used with ``params.blind_travel_bearings > 0`` in place of
            ``blind_travel_body`` (needs ``pose_world`` for the robots' yaw).
        detection_body: ``(R, M, 2)`` the last observation's detections in Σ_i (m, NaN:
            not detected), used with ``params.detection_rows`` (Section 1d), Σ_MEAS from
            ``config.meas_cov_diag``.
        The arrays: as in :func:`safety_rows`; ``pose_world=None`` gives no wall rows.
    """
    per_bearing = params.blind_travel_bearings > 0
    use_last = blind and last_seen_body is not None and params.last_seen_radius_m > 0.0
    return safety_rows(
        mean_body=mean_body,
        cov_body=cov_body,
        detected=detected,
        velocity_est_body=velocity_est_body,
        pose_world=pose_world if params.walls else None,
        particles_body=particles_body,
        particle_mass=particle_mass,
        safety_distance_m=config.safety_distance_m,
        v_max_mps=config.v_max_mps,
        omega_max_radps=config.omega_max_radps,
        dt_s=config.dt_s,
        arena_size_m=config.arena_size_m,
        robot_radius_m=config.robot_radius_m,
        safety_risk=params.safety_risk,
        safety_gain=barrier_gain(params.safety_gain, config.dt_s),
        responsibility=params.responsibility,
        blind_bins=params.blind_bins if blind else 0,
        blind_risk=params.blind_risk,
        blind_speed_mps=params.blind_speed_mps,
        walls=params.walls,
        wall_gain=barrier_gain(params.wall_gain, config.dt_s),
        hold_band_m=params.safety_hold_band_m,
        hold_band_barrier=params.hold_band_barrier,
        recovery_mps=params.safety_recovery_mps,
        fov_rad=config.fov_rad if fov_rad is None else fov_rad,
        blind_density_risk=params.blind_density_risk,
        last_seen_body=last_seen_body if use_last else None,
        last_seen_age_s=last_seen_age_s if use_last else None,
        last_seen_radius_m=params.last_seen_radius_m,
        last_seen_max_age_s=params.last_seen_max_age_s,
        last_seen_release=params.last_seen_release,
        reach_sigma_m=risk_quantile(params.safety_risk) * float(max(config.meas_std[:2])),
        detection_range_m=config.detection_range_m,
        blind_travel_body=blind_travel_body if blind and not per_bearing else None,
        blind_travel_m=params.blind_travel_m,
        bearing_travel_m=bearing_travel_m if blind and per_bearing else None,
        bearing_travel_yaw_rad=None if pose_world is None else np.asarray(pose_world)[:, 2],
        lost_sigma_max_m=params.lost_sigma_max_m,
        particle_counts=particle_counts,
        undetected_quantile=params.undetected_quantile,
        bearing_cone_max_rad=math.radians(params.bearing_cone_max_deg),
        detection_body=detection_body if params.detection_rows else None,
        detection_cone=params.detection_cone,
        meas_cov_xy=np.diag(np.asarray(config.meas_cov_diag[:2], dtype=np.float64)),
        detection_sector=params.detection_sector,
        meas_clip_xy_m=(
            config.meas_noise_clip_sigma * float(config.meas_std[0]),
            config.meas_noise_clip_sigma * float(config.meas_std[1]),
        ),
    )


def hold_band(h: np.ndarray, band_m: float) -> np.ndarray:
    """The dead zone of the neighbour rows: ``g(h) = h − b`` above ``b``, 0 on ``[0, b]``, h below 0.

    The neighbour rows use ``ρ γ g(h)`` as a cap on their approach
    (:func:`neighbour_row_offsets`): approach only beyond ``D_s + b``, hold within the
    band unless j's predicted closing leaves no room (then the barrier's own retreat),
    retreat below ``D_s``. g is continuous, non-decreasing and ≥ 0 exactly where h ≥ 0, so the set
    ``h ≥ 0`` stays forward invariant. Without the band the estimate's step-to-step
    noise (σ ≈ 0.3 m for a detected neighbour) flipped the robot between approach and
    retreat every step around h = 0 (measured: two robots head-on, forward speed
    alternating +0.2 / −0.38 m/s for 25 steps).

    Args:
        h: ``(...)`` barrier values (m). band_m: b ≥ 0 (m).
    """
    h = np.asarray(h, dtype=np.float64)
    if band_m <= 0.0:
        return h
    return np.where(h > band_m, h - band_m, np.minimum(h, 0.0))


def neighbour_row_offsets(
    h: np.ndarray,
    g: np.ndarray,
    pred_mps: np.ndarray | None,
    gain: float,
    responsibility: float,
    recovery_mps: float = math.inf,
) -> np.ndarray:
    """Offsets ``b`` (m/s) of the neighbour rows ``n · v ≤ b`` (Section 1), hold band included.

    ``b = min(γ h − c(h), ρ γ g(h))`` with ``c(h) = max((1 − ρ) γ h, p)``: the first term
    is the discrete-time barrier with shared responsibility (what i may close when j
    closes at ``c``; ``h_{k+1} ≥ (1 − γ dt) h_k``), the second the hold band's share
    (:func:`hold_band`: approach only beyond ``D_s + b``). The band only ever takes
    approach away: it never demands a retreat that the barrier does not. Below D_s
    (``g = h``) and with no band the two coincide with the barrier row. Measured on
    the earlier ``γ g − max((1 − ρ) γ g, p)``: within the band it demanded retreat at
    the full predicted closing ``p`` although the barrier left ``γ h`` to spare (up to
    0.75 m/s at b = 0.3 m): a pfcbf robot (N = 6, β = 120°, seed 0, robot 1, steps
    936-946) facing a settled neighbour 3 m away, seen, whose Eq. 20 prediction closed
    at 0.3-0.7 m/s, was told to back off at 0.44 m/s into neighbours it could not see,
    fell to the safe fallback, turned to the neighbour, was turned back by its FoV
    levels, and ω flipped every step.

    **Recovery cap** (``recovery_mps`` = r, ``ControllerParams.safety_recovery_mps``):
    below D_s the barrier's term ``γ h`` is used as ``max(γ h, −r)`` (and ``γ g`` likewise),
    i.e. the extended class-K function of the barrier saturates at the recovery speed
    r: a pair deep inside D_s is asked to separate at r, not at ``γ |h|``. With the
    default γ = 2.5 1/s a detected pair packed 1.1 m apart had ``γ |h| ≈ 4 m/s``, four
    times v_max, so the collision rows could never be met, every packed robot sat in
    the safe fallback and stopped (Section 1f). The cap keeps what the barrier is for
    below D_s: ``h`` does not decrease (the row still demands a retreat, ``b ≤ 0`` when
    j is predicted to take its share), so the pair's distance to each other's band
    never shrinks; only the rate at which D_s is regained is bounded. ``inf``
    (the default) is the uncapped barrier.

    Args:
        h: ``(...)`` barrier values (m). g: ``hold_band(h, b)``, same shape.
        pred_mps: the closing speed j's model predicts along the line of sight (m/s),
            same shape, or None (j assumed to take its share).
        gain: γ (1/s, already capped by :func:`barrier_gain`). responsibility: ρ.
        recovery_mps: r (m/s), > 0, or inf (no cap).

    Returns:
        ``(...)`` the offsets (m/s).
    """
    if math.isfinite(recovery_mps):  # γ max(h, −r/γ) = max(γ h, −r)
        h = np.maximum(h, -recovery_mps / gain)
        g = np.maximum(g, -recovery_mps / gain)
    share = (1.0 - responsibility) * gain * h
    closing = share if pred_mps is None else np.maximum(share, pred_mps)
    return np.minimum(gain * h - closing, responsibility * gain * g)


def safety_rows(
    *,
    mean_body: np.ndarray,
    cov_body: np.ndarray,
    detected: np.ndarray,
    velocity_est_body: np.ndarray | None = None,
    pose_world: np.ndarray | None,
    particles_body: np.ndarray | None,
    particle_mass: np.ndarray | None,
    safety_distance_m: float,
    v_max_mps: float,
    omega_max_radps: float,
    dt_s: float,
    arena_size_m: float,
    robot_radius_m: float,
    safety_risk: float,
    safety_gain: float,
    responsibility: float,
    blind_bins: int,
    blind_risk: float,
    blind_speed_mps: float,
    walls: bool,
    wall_gain: float,
    hold_band_m: float = 0.0,
    hold_band_barrier: bool = True,
    recovery_mps: float = math.inf,
    fov_rad: float = 2.0 * math.pi,
    blind_density_risk: float = 0.0,
    last_seen_body: np.ndarray | None = None,
    last_seen_age_s: np.ndarray | None = None,
    last_seen_radius_m: float = 0.0,
    last_seen_max_age_s: float = math.inf,
    last_seen_release: str = "point",
    reach_sigma_m: float = 0.0,
    detection_range_m: float = math.inf,
    blind_travel_body: np.ndarray | None = None,
    blind_travel_m: float = 0.0,
    bearing_travel_m: np.ndarray | None = None,
    bearing_travel_yaw_rad: np.ndarray | None = None,
    lost_sigma_max_m: float = math.inf,
    particle_counts: np.ndarray | None = None,
    undetected_quantile: str = "gaussian",
    bearing_cone_max_rad: float = 0.0,
    detection_body: np.ndarray | None = None,
    meas_cov_xy: np.ndarray | None = None,
    detection_cone: bool = True,
    detection_sector: bool = False,
    meas_clip_xy_m: tuple[float, float] | None = None,
) -> SafetyRows:
    """All collision rows of every robot (module docstring, Sections 1-3).

    Args:
        mean_body, cov_body: ``(R, M, 2)``, ``(R, M, 2, 2)`` estimates in Σ_i.
        detected: ``(R, M)`` bool, neighbour in the last observation.
        velocity_est_body: ``(R, M, 2)`` the neighbours' model velocities in Σ_i (m/s),
            or None (taken as 0: every neighbour assumed to take its share).
        pose_world: ``(R, 3)`` own poses, for the wall rows (None: no wall rows).
        particles_body: ``(R, P, 2)`` particles of every neighbour in Σ_i, or None
            (no blind rows).
        particle_mass: ``(R, P)`` ``1/P_j`` for particles of *undetected* neighbours,
            0 otherwise.
        last_seen_body, last_seen_age_s: ``(R, M, 2)`` m and ``(R, M)`` s, the
            neighbours' last-seen points in Σ_i (NaN: never seen) and their ages, or
            None (no last-seen rows; :func:`last_seen_rows`).
        blind_travel_body: ``(R, 2)`` the blind travel ``e`` in Σ_i (m), or None (no
            budget row; Section 2d). blind_travel_m: the budget B (m); 0: no row. (The
            pipeline passes None for a one-robot team: no neighbour can be met blind.)
        bearing_travel_m, bearing_travel_yaw_rad: ``(R, K_b)`` the approach per budget
            bearing (m) and ``(R,)`` the robots' yaw, or None (no per-bearing rows;
            Section 2e, :func:`bearing_travel_rows`); the budget is ``blind_travel_m``.
        particle_counts: ``(R, M)`` particles per neighbour column of ``particles_body``
            (needed by ``undetected_quantile="particles"``).
        undetected_quantile: ``"gaussian"`` (the Gaussian fit's ``z σ_n``) or
            ``"particles"`` (:func:`particle_halfplane_offsets`) for the lines of
            undetected neighbours; detected ones always use the Gaussian (the
            camera's noise).
        hold_band_barrier: :func:`neighbour_row_offsets` (True) or the earlier
            ``γ g − max((1 − ρ) γ g, p)`` (False, ablation).
        recovery_mps: the recovery cap of :func:`neighbour_row_offsets` (m/s); inf: none.
        bearing_cone_max_rad: cap on the half-angle α of the bearing cone of the
            neighbour rows within D_s (Section 1b, :func:`bearing_cone`); 0: none
            (one row along the mean's line of sight).
        detection_body, meas_cov_xy: ``(R, M, 2)`` the last observation's detections in
            Σ_i (m, NaN: not detected) and ``(2, 2)`` Σ_MEAS of the position (m²), for
            the rows on the camera's own report (Section 1d, :func:`detection_rows`);
            None: no such rows.
        detection_cone: with the detection rows and ``bearing_cone_max_rad > 0``, the
            edges of the detection's own cone of bearings (Σ_MEAS) where its barrier
            ``h_z < 0`` and the posterior's cone applies (Section 1d; False: ablation).
        detection_sector, meas_clip_xy_m: with the detection rows, a report outside
            the camera sector (:func:`detection_sector_rows`, Section 1e; the noise clip
            per axis in m) pushes no robot away (its neighbour row's offset is floored
            at 0) and adds approach-only rows along the sector's edges and axis.
        The rest: scenario quantities and the ``ControllerParams`` fields of the
        same names.

    Returns:
        :class:`SafetyRows` with up to ``K = 7 M + 2 blind_bins + 5`` rows per robot
        (padded; without the detection rows ``M`` fewer, or ``3 M`` with the bearing
        cone, whose edges they bring too; without the bearing cone ``2 M`` fewer, or
        ``4 M`` with the detection rows).
    """
    mu = np.asarray(mean_body, dtype=np.float64)
    R, M = mu.shape[0], mu.shape[1]
    m_arc = arc_margin(v_max_mps, omega_max_radps, dt_s)
    gain = responsibility * safety_gain
    blocks_A, blocks_b, blocks_k, blocks_h = [], [], [], []

    def add(block: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> None:
        for blocks, x in zip((blocks_A, blocks_b, blocks_k, blocks_h), block, strict=True):
            blocks.append(x)

    cone_post = np.zeros((R, M), dtype=bool)  # where the posterior's cone applies
    sector = None
    if detection_sector and detection_body is not None and meas_clip_xy_m is not None and M:
        sector = detection_sector_rows(detection_body, fov_rad, detection_range_m, meas_clip_xy_m)

    if M:
        n, s = neighbour_halfplanes(mu, cov_body, risk_quantile(safety_risk))
        det = np.asarray(detected, dtype=bool)
        if undetected_quantile == "particles" and particles_body is not None:
            if particle_counts is None:
                raise ValueError('undetected_quantile="particles" needs particle_counts')
            s_pf = particle_halfplane_offsets(particles_body, particle_counts, n, safety_risk)
            s = np.where(det, s, s_pf)
        h = s - safety_distance_m - m_arc
        keep = det | (s > 0.0)
        if math.isfinite(lost_sigma_max_m):  # diffuse undetected beliefs: blind rows only
            sigma_n = (np.hypot(mu[..., 0], mu[..., 1]) - s) / risk_quantile(safety_risk)
            keep &= det | (sigma_n <= lost_sigma_max_m)
        A = np.zeros((R, M, 3))
        A[..., 0:2] = -n
        g = hold_band(h, hold_band_m)
        if velocity_est_body is None:
            pred = None
        else:
            ve = np.asarray(velocity_est_body, dtype=np.float64)
            pred = -(n[..., 0] * ve[..., 0] + n[..., 1] * ve[..., 1])
        if hold_band_barrier:
            b = neighbour_row_offsets(h, g, pred, safety_gain, responsibility, recovery_mps)
        else:  # the earlier rows (ablation): the band also demanded j's whole closing
            closing_j = (1.0 - responsibility) * safety_gain * g
            if pred is not None:
                closing_j = np.maximum(closing_j, pred)
            b = safety_gain * g - closing_j
        # undetected: never approach, but never pushed away by a belief (see docstring)
        b = np.where(det, b, np.maximum(b, 0.0))
        if sector is not None:  # Section 1e: no push from a report the camera contradicts
            _, _, contradicted = sector
            b = np.where(contradicted, np.maximum(b, 0.0), b)
        b = np.where(keep, b, np.inf)
        blocks_A.append(A)
        blocks_b.append(b)
        blocks_k.append(np.where(keep, ROW_NEIGHBOUR, -1).astype(np.int8))
        blocks_h.append(np.where(keep, h, np.inf))
        if bearing_cone_max_rad > 0.0:  # Section 1b: within D_s, the bearing's cone
            # undetected: the half-plane bound only (Section 1b)
            h_cone = np.where(keep & det, h, np.inf)
            cone_post = h_cone < 0.0
            for edge in _cone_rows(mu, cov_body, n, b, h_cone, bearing_cone_max_rad, safety_risk):
                add(edge)

    if detection_body is not None and meas_cov_xy is not None and M:
        # Section 1d: the camera's own report bounds the approach, never pushes
        n_z, s_z = detection_rows(detection_body, meas_cov_xy, risk_quantile(safety_risk))
        det_rows = _approach_only_rows(n_z, s_z, ROW_NEIGHBOUR, safety_distance_m, m_arc, gain)
        add(det_rows)
        if detection_cone and bearing_cone_max_rad > 0.0:  # Section 1d: the detection's cone
            z_body = np.where(np.isfinite(s_z)[..., None], detection_body, 0.0)
            cov_z = np.broadcast_to(np.asarray(meas_cov_xy, np.float64), z_body.shape + (2,))
            _, b_z, _, h_z = det_rows
            h_z = np.where(cone_post, h_z, np.inf)  # only where the posterior's cone is
            for edge in _cone_rows(z_body, cov_z, n_z, b_z, h_z, bearing_cone_max_rad, safety_risk):
                add(edge)

    if sector is not None:  # Section 1e: the sector's edges and axis, approach only
        n_s, clear_s, _ = sector
        for n_k in n_s:
            n_k = np.broadcast_to(n_k, clear_s.shape + (2,))
            add(_approach_only_rows(n_k, clear_s, ROW_CONE, safety_distance_m, m_arc, gain))

    if blind_bins > 0 and particles_body is not None and M:
        # beyond this range a row allows ≥ v_max: it would be pruned
        r_cut = safety_distance_m + m_arc + v_max_mps / max(gain, 1e-12)
        rep, found = blind_representatives(
            particles_body, particle_mass, blind_bins, blind_risk, r_cut
        )
        r = np.hypot(rep[..., 0], rep[..., 1])
        safe_r = np.where(found & (r > 1e-9), r, 1.0)
        A = np.zeros((R, blind_bins, 3))
        A[..., 0] = -np.where(found, rep[..., 0] / safe_r, 0.0)
        A[..., 1] = -np.where(found, rep[..., 1] / safe_r, 0.0)
        h = r - safety_distance_m - m_arc
        blocks_A.append(A)
        # a robot may creep (v_b) towards a possibly occupied direction only while the
        # representative is beyond D_s; within it, it may not approach at all
        floor = np.where(h > 0.0, blind_speed_mps, 0.0)
        blocks_b.append(np.where(found, np.maximum(floor, gain * h), np.inf))
        blocks_k.append(np.where(found, ROW_BLIND, -1).astype(np.int8))
        blocks_h.append(np.where(found, h, np.inf))

    if blind_density_risk > 0.0 and blind_bins > 0 and M and fov_rad < 2.0 * math.pi:
        A, b, h = blind_density_rows(
            mu,
            cov_body,
            np.asarray(detected, dtype=bool),
            blind_bins,
            blind_density_risk,
            safety_distance_m + m_arc + v_max_mps / max(gain, 1e-12),
            fov_rad,
        )
        blocks_A.append(A)
        blocks_b.append(b)
        blocks_k.append(np.where(np.isfinite(b), ROW_DENSITY, -1).astype(np.int8))
        blocks_h.append(h)

    if last_seen_body is not None and last_seen_age_s is not None and M and last_seen_radius_m > 0:
        n_c, h_c = last_seen_rows(
            last_seen_body,
            last_seen_age_s,
            np.asarray(detected, dtype=bool),
            radius_m=last_seen_radius_m,
            reach_sigma_m=reach_sigma_m,
            v_max_mps=v_max_mps,
            fov_rad=fov_rad,
            detection_range_m=detection_range_m,
            max_age_s=last_seen_max_age_s,
            release=last_seen_release,
        )
        add(_approach_only_rows(n_c, h_c, ROW_LAST_SEEN, safety_distance_m, m_arc, gain))

    if blind_travel_body is not None and blind_travel_m > 0.0:
        e = np.asarray(blind_travel_body, dtype=np.float64)
        r = np.hypot(e[:, 0], e[:, 1])
        on = r > 1e-6
        safe_r = np.where(on, r, 1.0)
        A = np.zeros((R, 1, 3))
        A[:, 0, 0] = -np.where(on, e[:, 0] / safe_r, 0.0)
        A[:, 0, 1] = -np.where(on, e[:, 1] / safe_r, 0.0)
        left = blind_travel_m - r
        blocks_A.append(A)
        blocks_b.append(np.where(on, np.maximum(0.0, left / dt_s), np.inf)[:, None])
        blocks_k.append(np.where(on, ROW_BUDGET, -1).astype(np.int8)[:, None])
        blocks_h.append(np.where(on, left, np.inf)[:, None])
        if v_max_mps * dt_s > blind_travel_m:
            # one step could spend more than the whole budget in a direction the vector
            # does not point along (with a zero vector: any): the per-bearing rows of 24
            # never-approached bearings in Σ_i with the vector's remaining budget cap every
            # direction outside the view. Not written when v_max dt ≤ B.
            A, b, h = bearing_travel_rows(
                np.zeros((R, 24)), np.zeros(R), left[:, None], dt_s, v_max_mps, fov_rad
            )
            blocks_A.append(A)
            blocks_b.append(b)
            blocks_k.append(np.where(np.isfinite(b), ROW_BUDGET, -1).astype(np.int8))
            blocks_h.append(h)

    if bearing_travel_m is not None and blind_travel_m > 0.0:
        if bearing_travel_yaw_rad is None:
            raise ValueError("bearing_travel_m needs bearing_travel_yaw_rad (the robots' yaw)")
        A, b, h = bearing_travel_rows(
            bearing_travel_m, bearing_travel_yaw_rad, blind_travel_m, dt_s, v_max_mps, fov_rad
        )
        blocks_A.append(A)
        blocks_b.append(b)
        blocks_k.append(np.where(np.isfinite(b), ROW_BUDGET, -1).astype(np.int8))
        blocks_h.append(h)

    if walls and pose_world is not None:
        nw, w = wall_clearances(pose_world, arena_size_m, robot_radius_m)
        A = np.zeros((R, 4, 3))
        A[..., 0:2] = -nw
        h = w - m_arc
        blocks_A.append(A)
        blocks_b.append(wall_gain * h)
        blocks_k.append(np.full((R, 4), ROW_WALL, dtype=np.int8))
        blocks_h.append(h)

    if not blocks_A:
        return SafetyRows(
            np.zeros((R, 0, 3)), np.zeros((R, 0)), np.zeros((R, 0), np.int8), np.zeros((R, 0))
        )
    return SafetyRows(
        A=np.concatenate(blocks_A, 1),
        b=np.concatenate(blocks_b, 1),
        kind=np.concatenate(blocks_k, 1),
        h=np.concatenate(blocks_h, 1),
    )
