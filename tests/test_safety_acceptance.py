"""The safety issue's acceptance sweeps (pfcbf at every team size, settling, crossing, the
filter against adversaries and random actions). The full sweeps are ``slow`` (run them
with ``pytest -m slow tests/test_safety_acceptance.py``); a representative subset runs in
CI. Every assertion is a property users rely on: no collision event, D_s held where the
robots see each other, a team that settles, arrivals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fov_marl.evaluation import run_episode
from fov_marl.infos import safety_of

#: the filter before the bearing cone, the fallback's tie rule and straight steps, the arc
#: guard, the hold clean-up and the blind travel budget per bearing (the single vector,
#: forgotten 10° inside the view, leaking in 30 s, the FoV levels above the look turn):
#: the counterfactuals below run on the
#: filter their episodes were found with (these changes send the episodes on other courses
#: that stay clear even without the rows they test)
#: the arc guard before it could stop a creep to keep the turn (``arc_guard_stop``): every
#: counterfactual below was found with the guard slowing the turn, and the stop sends its
#: episode on another course (as it does the pfcbf mechanism tests); and the filter before
#: its rows on the camera's own report (``detection_rows``, safety Section 1d) and its
#: release of last-seen points by their uncertainty (``last_seen_release``, Section 2c),
#: which every counterfactual below predates too; and before the budget was cleared while
#: no neighbour can be near (``blind_travel_reach``, Section 2f), and before the early look
#: waited for a steady course (``look_persistence_deg``), and before bearings started
#: spent by the neighbours seen inside D_s there (``blind_travel_prespend``, Section 2g)
_BEFORE_STOP = {
    "arc_guard_stop": False,
    "detection_rows": False,
    "last_seen_release": "point",
    "blind_travel_reach": False,
    "look_persistence_deg": 0.0,
    "blind_travel_prespend": False,
}
_BEFORE_CONE = {
    **_BEFORE_STOP,
    "bearing_cone_max_deg": 0.0,
    "fallback_tie_mps": 0.0,
    "fallback_straight": False,
    "arc_yaw_guard": False,
    "hold_cleanup": False,
    "blind_travel_bearings": 0,
    "blind_travel_view_deg": 10.0,
    "blind_travel_memory_s": 30.0,
    "look_yields_fov": False,
    # and the neighbour rows' hold band and keep-right as they were (before
    # hold_band_barrier and deadlock_release), so the counterfactuals keep their courses
    "hold_band_barrier": False,
    "deadlock_release": 0.2,
}
#: the filter's tracker as it was before the fused recovery of collapsed clouds
#: (``ess_recovery``): the filter's counterfactuals keep their courses on it
_BEFORE_FUSION = {"ess_recovery": "reseed"}
#: pfcbf's coverage settings before its budget went per bearing with the glance and
#: keep-right went off (``PFCBF_COVERAGE_DEFAULTS``): the pfcbf mechanism tests below were
#: found on them, and the new settings send their seeds on other courses
_PFCBF_BEFORE_BEARINGS = {
    **_BEFORE_STOP,
    "blind_travel_bearings": 0,
    "look_yields_fov": False,
    "deadlock_turn_deg": 60.0,
}


def _scaled(n: int) -> dict:
    L = 40.0 * math.sqrt(n / 6.0)
    return {"arena_size_m": L, "density_mean_m": (L / 2, L / 2)}


def _coverage(n, seed, steps=None, **kw):
    return run_episode("coverage", "pfcbf", seed, n_agents=n, max_steps=steps, **kw)


# --------------------------------------------------------------------------- CI subset
def test_pfcbf_dense_team_in_the_papers_arena_does_not_collide():
    """N = 12 in the 40 m arena: the first version collided here (1 event in 3 episodes)."""
    rec = _coverage(12, 0, steps=300)
    assert rec.collisions == 0, rec
    assert rec.min_distance > 1.5, rec


def test_pfcbf_team_at_120_settles_near_ideal():
    """N = 6, β = 120°: the team comes to rest (the first version kept moving at 0.37 m/s)
    and covers about as well as the ideal team on the same seed."""
    rec = _coverage(6, 3)
    ideal = run_episode("coverage", "ideal", 3, n_agents=6)
    assert rec.collisions == 0
    assert rec.mean_speed_last_50s < 0.05, rec
    assert rec.final_eta >= ideal.final_eta - 0.005, (rec.final_eta, ideal.final_eta)


def _pfcbf_actions(seed, steps, **controller):
    """``(T, 6, 3)`` the actions of a pfcbf team (N = 6, β = 120°) over one episode."""
    from fov_marl.baselines import make_policy
    from fov_marl.envs import fov_coverage_v0

    env = fov_coverage_v0.parallel_env(n_agents=6, max_cycles=steps)
    policy = make_policy("pfcbf", env, controller_params=controller or None)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    actions = []
    while env.agents:
        act = policy.act(obs)
        actions.append([act[a] for a in env.possible_agents])
        obs, *_ = env.step(act)
    return np.asarray(actions)


def test_settled_pfcbf_team_does_not_chatter():
    """The issue's "no chattering": once the team has settled (N = 6, β = 120°, seed 1,
    steps 200-600) no robot turns back and forth on alternate steps. Eq. 18's order by
    d_ij alone swapped two unseen neighbours on opposite sides every few steps, and
    their FoV levels turned the robot ±0.8 ω_max in turn; the FoV lead's hysteresis
    (``priority_hysteresis_m``) keeps the order: 1 isolated flip (ω 0.67, −0.2, 0.05 while
    the FoV levels changed their target) against 15. It removes the systematic swaps, not
    every one: over seeds 0-6 (2,400 robot-steps each) the ω flips are 0-9 per episode
    with the arc guard of ``safety`` Section 1c and 0-10 without it.

    Run without the lost FoV yield's latch (``lost_fov_yield_latch``), on the controller
    the hysteresis was measured with: the latch sends seed 1 on another course, on which
    5 flips come from another mechanism (a neighbour at the edge of the view whose
    detection flickers changes its ellipse distance d, so the slack of Eq. 16 lets its
    FoV rows go and brings them back on alternate steps; steps 338-364). Over seeds 0-9,
    steps 200-1000, the latch lowers the ω flips from 94 to 86. Also on the neighbour
    rows it was measured with (``hold_band_barrier`` off) and without keep-right's
    hysteresis (``deadlock_release`` 0.2): the shipped rows send seed 1 on another
    course with 2 flips here, while over seeds 0-9, steps 200-1000, they cut
    the flips from 66 / 66 / 139 (vx / vy / ω) to 13 / 9 / 59. Both runs on pfcbf's
    single-vector budget with keep-right (``_PFCBF_BEFORE_BEARINGS``), as found."""
    from fov_marl.metrics import action_chatter

    latch = {
        "lost_fov_yield_latch": False,
        "hold_band_barrier": False,
        "deadlock_release": 0.2,
        **_PFCBF_BEFORE_BEARINGS,
    }
    kept = action_chatter(_pfcbf_actions(1, 600, **latch)[200:])
    swapped = action_chatter(_pfcbf_actions(1, 600, priority_hysteresis_m=0.0, **latch)[200:])
    assert kept.sum() <= 1, kept
    assert swapped[2] >= 10, swapped  # the measurement discriminates


def test_lost_fov_yield_latch_stops_a_pinned_robot_turning_back_and_forth():
    """Seed 3 (N = 6, β = 120°), robot 3 at steps 925-945, three neighbours lost behind it
    at 2-5 m: its blind rows pinned it, the lost FoV rows yielded, it turned left towards
    u* and found a free direction, was no longer stalled, so the lost rows turned it back
    right at ω_max, which pinned it again (5 ω flips in those 20 steps, 7 over the last
    250). The latch (``lost_fov_yield_latch``) keeps the yield while u* translates. On
    the budget leak the episode was found with (30 s; pfcbf's 120 s sends it elsewhere)
    and on the neighbour rows and keep-right of then (``hold_band_barrier`` off,
    ``deadlock_release`` 0.2: the shipped ones send it elsewhere too, with no flips
    either way). And on pfcbf's single-vector budget with keep-right
    (``_PFCBF_BEFORE_BEARINGS``)."""
    from fov_marl.metrics import action_chatter

    leak = {
        "blind_travel_memory_s": 30.0,
        "hold_band_barrier": False,
        "deadlock_release": 0.2,
        **_PFCBF_BEFORE_BEARINGS,
    }
    latched = action_chatter(_pfcbf_actions(3, 945, **leak)[925:])
    unlatched = action_chatter(_pfcbf_actions(3, 945, lost_fov_yield_latch=False, **leak)[925:])
    assert latched.sum() == 0, latched
    assert unlatched[2] >= 4, unlatched  # the counterfactual chatters


def test_keep_right_hysteresis_stops_a_robot_flipping_vx():
    """Seed 5 (N = 6, β = 120°), robot 0 at steps 758-764: u* small (0.15 m/s), blind
    rows binding, the solution kept about a fifth of u*'s progress, so "keep right"
    (``deadlock_turn_deg``) was adopted on alternate steps and vx flipped between +0.1
    and −0.07 m/s (the slow chatter test's 7 vx flips). With the hysteresis
    (``deadlock_release`` 0.5) no flip in vx over the last 250 steps; without it, 7.
    Keep-right is off in coverage now (``PFCBF_COVERAGE_DEFAULTS``); the test runs pfcbf
    as it was found (``_PFCBF_BEFORE_BEARINGS``), for the mechanism the crossing uses."""
    from fov_marl.metrics import action_chatter

    kept = action_chatter(_pfcbf_actions(5, 1000, **_PFCBF_BEFORE_BEARINGS)[750:])
    flips = action_chatter(
        _pfcbf_actions(5, 1000, deadlock_release=0.2, **_PFCBF_BEFORE_BEARINGS)[750:]
    )
    assert kept[0] == 0, kept
    assert flips[0] >= 4, flips  # the counterfactual flips


def _stress(episode, tracker=None, **controller):
    """head_on, N = 12, β = 120°, random start; ``tracker`` / ``controller``: overrides of
    the filter's defaults (empty: the shipped filter)."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {"controller_params": controller, "tracker_params": tracker or {}}
    case = StressCase("head_on", 12, 120.0, "random", filter_kwargs=fk)
    return run_stress_episode(case, episode, 300)


@pytest.mark.parametrize("episode", [1, 2])
def test_filter_head_on_dense_team_regressions(episode):
    """The two collisions the wider sweep found after the first round (head-on adversary,
    N = 12, β = 120°): episode 1, a robot sliding blind at 1 m/s into one it had not seen
    in 26 s (blind travel budget); episode 2, a robot backing into one it had turned away
    from (last-seen rows). ``test_filter_regressions_collide_without_the_new_rows``
    (slow) shows both collide without them."""
    ep = _stress(episode)
    assert ep["collisions"] == 0, ep
    assert ep["min_distance_m"] > 1.0, ep


def test_filter_wait_charge_regression():
    """wait_charge, N = 12, β = 120°, random start, seed 101: it collided (min 0.65 m at
    step 121) when the filter let lost neighbours' FoV levels yield and dropped the
    half-planes of diffuse beliefs (``lost_fov_yield``, ``lost_sigma_max_m = 2``); with the
    shipped filter defaults both are off (measured min 2.36 m)."""
    from fov_marl.stress import StressCase, run_stress_episode

    ep = run_stress_episode(StressCase("wait_charge", 12, 120.0, "random"), 101, 300)
    assert ep["collisions"] == 0, ep
    assert ep["min_distance_m"] > 1.5, ep


@pytest.mark.slow
def test_filter_wait_charge_regression_collides_with_yield_and_sigma_cut():
    from fov_marl.stress import StressCase, run_stress_episode

    # on the filter it was found with (1 m blind travel budget; with the shipped 0.5 m this
    # episode keeps clear even with both ablations on)
    # (and before the FoV lead's hysteresis, and before the yield's latch, which sends it
    # on a course that stays clear)
    cp = {
        "lost_fov_yield": True,
        "lost_fov_yield_latch": False,
        "lost_sigma_max_m": 2.0,
        "blind_travel_m": 1.0,
        "priority_hysteresis_m": 0.0,
        **_BEFORE_CONE,
    }
    fk = {"controller_params": cp, "tracker_params": _BEFORE_FUSION}
    case = StressCase("wait_charge", 12, 120.0, "random", filter_kwargs=fk)
    assert run_stress_episode(case, 101, 300)["collisions"] > 0


def test_filter_packed_wall_start_spinning_regression():
    """spin_charge, N = 8, β = 360°, packed 1.1 m apart along a wall, seed 900: two robots in
    the safe fallback kept their QP's escape across each other's uncertain line of sight
    while turning at ω_max and closed from 1.043 m to 1.015 m (contact at 1.0) in step 20.
    With the bearing cone of the rows within D_s (``safety`` Section 1b) and the
    fallback's straight steps no pair gets closer than it started."""
    from fov_marl.stress import StressCase, run_stress_episode

    ep = run_stress_episode(StressCase("spin_charge", 8, 360.0, "wall"), 900, 60)
    assert ep["collisions"] == 0, ep
    assert ep["min_distance_m"] >= 1.1 - 1e-6, ep


@pytest.mark.slow
def test_filter_packed_wall_start_dips_without_the_bearing_cone():
    """spin_charge, N = 12, β = 360°, wall start, seed 1001: no pair closer than its 1.1 m
    start with the bearing cone; 1.0957 m without it (straight fallback steps alone)."""
    from fov_marl.stress import StressCase, run_stress_episode

    ep = run_stress_episode(StressCase("spin_charge", 12, 360.0, "wall"), 1001, 300)
    assert ep["min_distance_m"] >= 1.1 - 1e-6, ep
    # on the filter it was found with: before the arc guard and the budget per bearing,
    # either of which also keeps this episode at 1.1 m without the cone
    # (and before the detection rows, which also keep it at 1.1 m: _BEFORE_STOP)
    cp = {
        "bearing_cone_max_deg": 0.0, "arc_yaw_guard": False, "blind_travel_bearings": 0,
        **_BEFORE_STOP,
    }  # fmt: skip
    fk = {"controller_params": cp, "tracker_params": _BEFORE_FUSION}  # and its tracker
    off = StressCase("spin_charge", 12, 360.0, "wall", filter_kwargs=fk)
    assert run_stress_episode(off, 1001, 300)["min_distance_m"] < 1.099


@pytest.mark.parametrize("guard", [True, False])
def test_filter_packed_wall_start_no_dip_on_the_arc(guard):
    """straight, N = 2, β = 45°, packed 1.1 m apart along a wall facing it, seed 7000 (the
    full stress grid's closest pair, 1.098 m): neither robot sees the other, each holds
    its row (``v_y`` away) but creeps forward while turning at ω_max, and the arc of that
    step curved both 1 mm towards each other. With the yaw-rate guard (``safety``
    Section 1c) no pair gets closer than it started; without it the dip comes back."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {"controller_params": {"arc_yaw_guard": guard}}
    ep = run_stress_episode(StressCase("straight", 2, 45.0, "wall", filter_kwargs=fk), 7000, 60)
    assert ep["collisions"] == 0, ep
    if guard:
        assert ep["min_distance_m"] >= 1.1 - 1e-9, ep
    else:
        assert ep["min_distance_m"] < 1.099, ep


@pytest.mark.parametrize("cleanup", [True, False])
def test_filter_packed_wall_start_no_creep_within_the_tolerance(cleanup):
    """wait_charge, N = 4, β = 120°, wall start, seed 1101 (the packed-start sweep's closest
    pair after the arc guard, 1.099874 m): a robot's cascade met its rows within its
    tolerance (κ* 6e-4, status "solved") and backed at 0.6 mm/s into an unseen neighbour
    1.1 m behind it. With the hold clean-up (``controller.hold_cleanup``) no pair gets
    closer than it started; without it (``hold_cleanup=False``) the creep is back."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {}
    if not cleanup:
        # found on the single-vector travel budget (10° margin, 30 s leak, no glance); the
        # per-bearing one (safety Section 2e) happens to stop this creep as well
        cp = {"hold_cleanup": False, "blind_travel_bearings": 0, "blind_travel_view_deg": 10.0}
        cp.update(blind_travel_memory_s=30.0, look_yields_fov=False, **_BEFORE_STOP)
        fk = {"controller_params": cp}
    case = StressCase("wait_charge", 4, 120.0, "wall", filter_kwargs=fk)
    ep = run_stress_episode(case, 1101, 300)
    assert ep["collisions"] == 0, ep
    if cleanup:
        assert ep["min_distance_m"] >= 1.1 - 1e-9, ep
    else:
        assert ep["min_distance_m"] < 1.09995, ep


@pytest.mark.parametrize("bearings", [24, 0])
def test_filter_narrow_view_edge_regression(bearings):
    """wait_charge, N = 24, β = 45°, head_on_pair start, seed 300: with the filter's old
    1 m blind travel budget a robot drove at 0.9 m/s along the edge of its view into a
    neighbour parked just outside it (unseen for 44 s, belief 8 m away) and touched at
    0.95 m in step 250. With 0.5 m, and since the arc guard (safety Section 1c) sent the
    episode on another course, a robot drove forward (in view, so the single vector's
    budget was zeroed every step) in bursts towards a neighbour parked 2.08 m away at
    −34° to −38°, unseen for 40 s, and closed to 1.41 m: 0.67 m of blind approach on a
    0.5 m budget. With the budget per bearing (safety Section 2e, the shipped 24
    bearings) it keeps 2.54 m; the single vector is kept here as the counterfactual."""
    from fov_marl.stress import StressCase, run_stress_episode

    cp = {"blind_travel_bearings": bearings}
    if not bearings:  # the vector as it was then: 10° margin, 30 s leak, no glance, and
        # the neighbour rows of then (the shipped ones send it elsewhere: 2.45 m)
        cp.update(
            blind_travel_view_deg=10.0, blind_travel_memory_s=30.0, look_yields_fov=False,
            hold_band_barrier=False, **_BEFORE_STOP,
        )  # fmt: skip
    fk = {"controller_params": cp}
    if not bearings:  # and the tracker of then (the fused recovery: 2.36 m)
        fk["tracker_params"] = _BEFORE_FUSION
    case = StressCase("wait_charge", 24, 45.0, "head_on_pair", filter_kwargs=fk)
    ep = run_stress_episode(case, 300, 260)
    assert ep["collisions"] == 0, ep
    if bearings:
        assert ep["min_distance_m"] > 2.0, ep
    else:
        assert ep["min_distance_m"] < 1.5, ep


@pytest.mark.parametrize("seed", [5, 10])
def test_filter_keeps_a_well_behaved_policys_progress(seed):
    """A policy that drives where it looks (pfcbf, N = 6, β = 120°) keeps its coverage
    behind the filter: η after 30 s at least 93% of its η alone (measured 0.971 / 0.995
    against 0.994 / 0.996 for seeds 5 / 10; 0.969 / 0.964 before pfcbf read the actions
    the filter applied, ``adopt_applied``). The per-bearing budget makes it glance
    sideways every ~1.3 m; before the glance outranked the FoV levels
    (``look_yields_fov``) that cut its translation: 0.829 / 0.499 (the counterfactual
    below). With the credit for backing away (``blind_travel_credit_m = 0.5``, the
    previous release) it kept 0.964 / 0.958; over seeds 0-14 then, 12 kept at least 96%,
    and seeds 7, 9 and 13 lagged at 30 s (0.38-0.62 of η alone: the particles of unseen
    neighbours block them) and reached the normalised threshold at 38, 88 and 42 s."""
    alone = run_episode("coverage", "pfcbf", seed, n_agents=6, max_steps=150)
    filt = run_episode("coverage", "pfcbf", seed, n_agents=6, max_steps=150, safety_filter=True)
    assert filt.collisions == 0
    assert filt.final_eta >= 0.93 * alone.final_eta, (filt.final_eta, alone.final_eta)


@pytest.mark.parametrize("stop, alone_min, alone_max", [(True, 0.3, 1.0), (False, 0.0, 0.05)])
def test_narrow_view_team_turns_to_look_instead_of_standing_still(stop, alone_min, alone_max):
    """pfcbf at β = 45° (N = 6, seed 7): a blind row straight ahead holds (b = 0), the QP
    keeps a 0.01 m/s creep along it and the look turn; the arc guard (safety Section 1c)
    used to slow that turn to nothing, so the robots neither moved nor looked: η 0.033
    after 30 s (0.059 after 60 s). With ``arc_guard_stop`` the robot stops the creep and
    turns: measured 0.45 after 30 s (0.96 after 60 s), no collision. Behind the filter
    too (β = 90°, seed 0): η after 30 s 0.53 without, 0.98 with (measured)."""
    cp = {"arc_guard_stop": stop}
    rec = run_episode(
        "coverage", "pfcbf", 7, n_agents=6, fov_deg=45.0, max_steps=150,
        policy_kwargs={"controller_params": cp},
    )  # fmt: skip
    assert rec.collisions == 0 and rec.safety_violations == 0
    assert alone_min <= rec.final_eta <= alone_max, rec.final_eta


@pytest.mark.parametrize("stop, lo, hi", [(True, 0.9, 1.0), (False, 0.0, 0.7)])
def test_filter_narrow_view_turns_to_look_instead_of_standing_still(stop, lo, hi):
    """The same stall behind the filter (pfcbf, β = 90°, N = 6, seed 0): η after 30 s.
    The counterfactual runs on the filter of then (before ``blind_travel_reach``, which
    alone lifts it out of the stall)."""
    fcp = (
        {"arc_guard_stop": stop}
        if stop
        else {"arc_guard_stop": False, "blind_travel_reach": False, "look_persistence_deg": 0.0}
    )
    rec = run_episode(
        "coverage", "pfcbf", 0, n_agents=6, fov_deg=90.0, max_steps=150, safety_filter=True,
        policy_kwargs={"controller_params": {"arc_guard_stop": stop}},
        safety_filter_kwargs={"controller_params": fcp},
    )  # fmt: skip
    assert rec.collisions == 0 and rec.safety_violations == 0
    assert lo <= rec.final_eta <= hi, rec.final_eta


@pytest.mark.parametrize("credit_m", [0.0, 0.5])
def test_filter_budget_gives_no_credit_for_backing_away(credit_m):
    """head_on, N = 12, β = 120°, head_on_pair start, seed 9000: the one D_s breach from
    a start outside D_s in the full stress grid (760 cases) with the previous release,
    whose per-bearing budget let moving away from a bearing build up to B = 0.5 m of
    credit towards it. A robot backed 0.49 m away from a bearing while the head-on
    neighbour there followed it (unseen: its belief was 7 m off), then drove 0.9 m
    towards it without looking, from 2.51 m to 1.654 m. Without credit (the default,
    safety Section 2e) it kept 2.426 m (2.539 m since the bias test); the credit is the counterfactual (1.828 m since
    the tracker's bias test, which sends the episode on a slightly different course:
    D_s still broken)."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {"controller_params": {"blind_travel_credit_m": credit_m}}
    if credit_m > 0.0:  # on the tracker and guard of then (both send it elsewhere)
        fk["tracker_params"] = _BEFORE_FUSION
        fk["controller_params"].update(_BEFORE_STOP)
    case = StressCase("head_on", 12, 120.0, "head_on_pair", filter_kwargs=fk)
    ep = run_stress_episode(case, 9000, 300)
    assert ep["collisions"] == 0, ep
    if credit_m == 0.0:
        assert ep["min_distance_m"] >= 2.0, ep
    else:
        assert ep["min_distance_m"] < 1.9, ep


@pytest.mark.parametrize("bias_alpha", [0.2, 0.0])
def test_filter_holds_d_s_when_a_seen_neighbours_cloud_overshoots(bias_alpha):
    """chase_last_seen, N = 24, β = 120°, random start, seed 9100 (the second full stress
    grid's one D_s event from a start outside D_s, a known issue until the tracker's bias
    test). Robot 12 saw robot 7 parked 2.3 m ahead, but its constant-velocity particles
    ran on 0.7-0.9 m beyond it with a std of 0.16-0.2 m, the 95% ellipse excluding the
    truth, and it drove on, seeing it, to 1.977 m. The bias test (``recovery_bias_alpha``
    0.2, tracker step 4) re-seeds such a cloud around the detections: D_s held (2.49 m).
    Its counterfactual, α = 0 (the test off), broke D_s again where it was traced; it
    runs on the neighbour rows of then (``hold_band_barrier`` off; the shipped rows send
    it on a course that keeps 2.40 m without the test). The course is chaotic: on the
    fresh install of 2026-12-07 (the same code) the counterfactual kept 2.419 m, so only
    its absence of collisions is asserted; the α = 0.2 case asserts D_s."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {"tracker_params": {"recovery_bias_alpha": bias_alpha}}
    if bias_alpha == 0.0:  # and the tracker's re-seed of then (before ``ess_recovery``)
        fk["controller_params"] = {"hold_band_barrier": False, **_BEFORE_STOP}
        fk["tracker_params"] = {**_BEFORE_FUSION, "recovery_bias_alpha": 0.0}
    case = StressCase("chase_last_seen", 24, 120.0, "random", filter_kwargs=fk)
    ep = run_stress_episode(case, 9100, 180)
    assert ep["collisions"] == 0, ep
    if bias_alpha > 0.0:  # the counterfactual's D_s break depends on round-off (docstring)
        assert ep["min_distance_m"] >= 2.0 and ep["violation_events"] == 0, ep


@pytest.mark.parametrize("ess_recovery", ["fuse", "reseed"])
def test_filter_survives_one_outlying_detection_of_a_seen_neighbour(ess_recovery):
    """straight, N = 12, β = 360°, wall start, seed 17000 (the full stress grid's one
    collision, run on a lent 16-core machine). Robots 1 and 2 stood 1.1 m apart along the
    wall, each seeing the other. At step 87 robot 2's detection of robot 1 was 1.2 m off
    (3.8 σ of Σ_MEAS: about 7e-4 per detection, tens of times per episode at N = 12). Its
    cloud (std 0.1 × 0.25 m) kept a handful of particles, so the effective-size test
    re-seeded it from N(z, Σ_MEAS) alone; z lay beyond the wall, the clamp put the cloud
    on robot 2 itself, and the rows, built on it, let robot 2 drive into robot 1 (0.997 m).
    The filter now fuses such a cloud with the detection (``ess_recovery="fuse"``, tracker
    step 4): no collision and no pair closer than the 1.1 m start. The counterfactual
    (``"reseed"``) collides, so the test can fail."""
    from fov_marl.stress import StressCase, run_stress_episode

    fk = {"tracker_params": {"ess_recovery": ess_recovery}}
    if ess_recovery == "reseed":  # the rows on the camera's own report (safety Section
        # 1d) also keep this one clear (1.1 m): the counterfactual is the filter of then
        fk["controller_params"] = {
            "detection_rows": False,
            "last_seen_release": "point",
            "blind_travel_reach": False,
            "look_persistence_deg": 0.0,
        }
    case = StressCase("straight", 12, 360.0, "wall", filter_kwargs=fk)
    ep = run_stress_episode(case, 17000, 100)
    if ess_recovery == "fuse":
        assert ep["collisions"] == 0 and ep["min_distance_m"] >= 1.1 - 1e-6, ep
    else:
        assert ep["collisions"] > 0, ep


def test_filter_budget_without_the_glance_stalls_a_well_behaved_policy():
    """The counterfactual of the test above: the per-bearing budget with the FoV levels
    above the glance (and the 30 s leak, as released before) stalls pfcbf (seed 10: η
    0.538 after 30 s against 0.996 alone; 0.499 when found), so that test can fail. It
    runs pfcbf as it was then, blind to the filter's changes to its actions
    (``adopt_applied=False``; knowing them: 0.599) and with its own settings of then
    (``_PFCBF_BEFORE_BEARINGS``: with its own glance pfcbf turns to look itself), and
    on the arc guard of then (``_BEFORE_STOP``: with the stop the filter without the glance
    kept 0.948 against 0.996, the robots turning in place where the guard had stopped
    their turn)."""
    pk = {"adopt_applied": False, "controller_params": _PFCBF_BEFORE_BEARINGS}
    alone = run_episode("coverage", "pfcbf", 10, n_agents=6, max_steps=150, policy_kwargs=pk)
    fk = {
        "controller_params": {
            "look_yields_fov": False, "blind_travel_memory_s": 30.0, **_BEFORE_STOP,
        }
    }  # fmt: skip
    filt = run_episode(
        "coverage", "pfcbf", 10, n_agents=6, max_steps=150, safety_filter=True,
        safety_filter_kwargs=fk, policy_kwargs=pk,
    )  # fmt: skip
    assert filt.final_eta < 0.6 * alone.final_eta, (filt.final_eta, alone.final_eta)


@pytest.mark.slow
def test_filter_narrow_view_edge_regression_collides_with_a_1m_budget():
    from fov_marl.stress import StressCase, run_stress_episode

    cp = {"blind_travel_m": 1.0, "priority_hysteresis_m": 0.0, **_BEFORE_CONE}  # found on
    fk = {"controller_params": cp, "tracker_params": _BEFORE_FUSION}
    case = StressCase("wait_charge", 24, 45.0, "head_on_pair", filter_kwargs=fk)
    assert run_stress_episode(case, 300, 260)["collisions"] > 0


@pytest.mark.parametrize("bearings", [24, 0])
def test_filter_lets_a_robot_travel_blind_only_its_budget_before_it_looks(bearings):
    """One robot commanded sideways (body frame) at full speed forever, alone in the
    arena: it gets at most B (+ one step) from where it last looked along its way (the
    single vector ``e``), or towards any bearing since it last looked at that bearing
    (the shipped budget per bearing), is then turned to look (the nominal yaw rate is
    0, so the turn counts as an intervention) and goes on: it is never stuck."""
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.wrappers import SafetyFilterWrapper
    from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS

    poses = np.array([[10.0, 20.0, 0.0], [35.0, 35.0, 0.0]])
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(n_agents=2, initial_poses=poses, fov_deg=120.0),
        # the budget alone: with blind_travel_reach (Section 2f) its far neighbour,
        # 29 m away, leaves it cleared for the whole run
        controller_params={"blind_travel_bearings": bearings, "blind_travel_reach": False},
    )
    env.reset(seed=0)
    budget = FILTER_CONTROLLER_DEFAULTS["blind_travel_m"]
    step_m = env.unwrapped.config.v_max_mps * env.unwrapped.config.dt_s
    cmd = {"robot_0": np.array([0.0, 1.0, 0.0], np.float32), "robot_1": np.zeros(3, np.float32)}
    path = 0.0
    turned = 0
    for _ in range(80):
        before = env.unwrapped.poses[0, :2].copy()
        _, _, _, _, infos = env.step(cmd)
        path += float(np.linalg.norm(env.unwrapped.poses[0, :2] - before))
        if bearings:
            assert env.pipeline._bearing_travel[0].max() <= budget + step_m + 1e-9
        else:
            e = env.pipeline._blind_travel_world[0]
            assert np.linalg.norm(e) <= budget + step_m + 1e-9
        s = safety_of(infos["robot_0"])
        if abs(s["applied_action"][2]) > 0.1:
            turned += 1
            assert s["intervened"]
    assert turned >= 5
    # measured: 8.2 m with the vector, 6.4 m per bearing (it also looks beside its way)
    assert path > (8.0 if bearings == 0 else 6.0), path


@pytest.mark.parametrize(
    "adversary, fov_deg, start",
    [("straight", 45.0, "random"), ("random", 45.0, "random"), ("charge_centre", 90.0, "random"),
     ("spin_charge", 120.0, "clustered"), ("wall_slide", 120.0, "wall"),
     ("rush", 45.0, "corner")],
)  # fmt: skip
@pytest.mark.parametrize("reach", [False, True])
def test_filter_no_bearing_is_approached_blind_beyond_the_budget(reach, adversary, fov_deg, start):
    """The property of the per-bearing budget (safety Section 2e), from the true poses
    alone: for each of the 24 budget bearings ψ_k, every robot's net approach
    ``n_k · (p_t − p_look)`` since the bearing's 15° sector was last wholly inside its
    view (``|ψ_k − yaw| ≤ β/2 − 7.5°``; at the start every bearing counts as looked at)
    or (with the option ``blind_travel_reach``, Section 2f) since its budget was last
    cleared because no neighbour could be near stays within B, one step and the arc's
    departure from the straight step (no leak, so the bound is exact), less what the
    neighbours the camera showed inside D_s there at that look had already used (Section
    2g: the shipped ``blind_travel_prespend``). And whenever the
    filter clears a robot's budget that way, every neighbour is truly farther than
    H = D_s + 2 B + 2 v_max dt: the reachable disks hold the truth."""
    from fov_marl.adversaries import make_adversary, make_start_poses
    from fov_marl.config import make_config
    from fov_marl.control.safety import arc_margin
    from fov_marl.envs import fov_coverage_v0
    from fov_marl.wrappers import SafetyFilterWrapper
    from fov_marl.wrappers.safety_filter import FILTER_CONTROLLER_DEFAULTS

    n, steps = 6, 150
    cfg = make_config(scenario="coverage", n_agents=n, fov_deg=fov_deg)
    poses = make_start_poses(start, cfg, np.random.default_rng(3))
    env = SafetyFilterWrapper(
        fov_coverage_v0.parallel_env(
            n_agents=n, fov_deg=fov_deg, initial_poses=poses, max_cycles=steps
        ),
        # the shipped budget: per bearing at every β, no leak, so the bound is exact
        controller_params={"blind_travel_reach": reach},
    )
    adv = make_adversary(adversary, env)
    pipe = env.pipeline
    cleared_rows: list[np.ndarray] = []
    clear = pipe._clear_reached

    def record(rows: np.ndarray) -> np.ndarray:  # the robots whose budget the rule zeroes
        cleared_rows.append(clear(rows))
        return cleared_rows[-1]

    pipe._clear_reached = record
    obs, _ = env.reset(seed=5)
    adv.reset(seed=6)
    B = FILTER_CONTROLLER_DEFAULTS["blind_travel_m"]
    H = cfg.safety_distance_m + 2.0 * B + 2.0 * cfg.v_max_mps * cfg.dt_s
    n_cleared = 0
    K = env.pipeline.controller_params.blind_travel_bearings
    bound = B + cfg.v_max_mps * cfg.dt_s
    bound += arc_margin(cfg.v_max_mps, cfg.omega_max_radps, cfg.dt_s) + 1e-6
    psi = 2.0 * math.pi * np.arange(K) / K
    n_w = np.stack([np.cos(psi), np.sin(psi)], -1)  # (K, 2)
    half = 0.5 * math.radians(fov_deg) - math.pi / K
    look = np.repeat(env.unwrapped.poses[:, None, :2], K, 1)  # (N, K, 2)
    # what the neighbours seen at the last look had already used (Section 2g)
    used_at_look = pipe._bearing_floor[:n].copy()
    worst = 0.0
    while env.agents:
        cleared_rows.clear()
        obs, *_ = env.step(adv.act(obs))
        p = env.unwrapped.poses
        approach = np.einsum("nkd,kd->nk", p[:, None, :2] - look, n_w)
        worst = max(worst, float((approach + used_at_look).max()))
        assert np.all(approach <= bound - used_at_look), (approach.max(), bound)
        rel = (psi[None, :] - p[:, 2:3] + math.pi) % (2.0 * math.pi) - math.pi
        seen = np.abs(rel) <= half + 1e-9
        look = np.where(seen[..., None], p[:, None, :2], look)
        used_at_look = np.where(seen, pipe._bearing_floor[:n], used_at_look)
        for rows in cleared_rows:
            for i in rows.tolist():
                d = np.hypot(*(p[:, :2] - p[i, :2]).T)
                assert np.delete(d, i).min() > H, (i, d, H)
                look[i] = p[i, :2]
                used_at_look[i] = 0.0
                n_cleared += 1
    assert worst > 0.5 * B  # the bound was approached: the test can fail
    # measured with the option: 306-337 clearings in the open starts; none without it
    assert (n_cleared > 0) == (reach and start == "random"), n_cleared


# --------------------------------------------------------------------------- slow sweeps
@pytest.mark.slow
@pytest.mark.parametrize(
    "n, seeds",
    [
        (6, range(20)),
        (12, range(20)),
        # seed 12 collided (min 0.54 m) on a664dd3 with arena-wide re-seeds of a belief
        # deleted in a fast turn; the local re-seed (TrackerParams.recovery_reseed) fixed it
        (24, range(20)),
        (48, range(5)),
    ],
)
def test_pfcbf_papers_arena_no_collisions(n, seeds):
    for seed in seeds:
        rec = _coverage(n, seed)
        assert rec.collisions == 0, (n, seed, rec)


@pytest.mark.slow
@pytest.mark.parametrize("memory_s, collides", [(120.0, False), (30.0, True)])
def test_pfcbf_budget_leak_blocks_a_slow_blind_creep(memory_s, collides):
    """N = 48, seed 4, with the tracker's bias test on (its course): with the budget's
    30 s leak a robot crept blind at 0.03 m/s (0.9 m of a 1 m budget in steady state) into
    a neighbour whose belief it held 24 m off (min 0.60 m); pfcbf's 120 s leak blocks a
    creep above 0.0083 m/s (min 2.32 m). The counterfactual runs on the neighbour rows
    and keep-right it was found with (``hold_band_barrier`` off, ``deadlock_release``
    0.2), on pfcbf's single-vector budget (``_PFCBF_BEFORE_BEARINGS``) and on the
    per-robot controller (``controller="loop"``): the batched controller, pfcbf's default
    since, agrees with it to 1e-10 per step, but over 1000 steps at N = 48 that sent this
    episode on another course where the creep does not arise (0 collisions, measured);
    the 120 s case runs on the default."""
    cp = {"blind_travel_memory_s": memory_s}
    pk = {}
    if collides:
        cp.update(hold_band_barrier=False, deadlock_release=0.2, **_PFCBF_BEFORE_BEARINGS)
        pk["controller"] = "loop"
    rec = _coverage(
        48, 4,
        policy_kwargs={
            "tracker_params": {"recovery_bias_alpha": 0.2},
            "controller_params": cp,
            **pk,
        },
    )  # fmt: skip
    assert (rec.collisions > 0) == collides, rec


@pytest.mark.slow
@pytest.mark.parametrize("n", [100, 200])
def test_pfcbf_scaled_arenas_no_collisions(n):
    for seed in range(3):
        rec = _coverage(n, seed, **_scaled(n))
        assert rec.collisions == 0, (n, seed, rec)


@pytest.mark.slow
def test_pfcbf_settles_in_every_seed_and_matches_ideal():
    for seed in range(20):
        rec = _coverage(6, seed)
        ideal = run_episode("coverage", "ideal", seed, n_agents=6)
        assert rec.mean_speed_last_50s < 0.05, (seed, rec)
        assert rec.final_eta >= 0.995 * ideal.final_eta, (seed, rec.final_eta, ideal.final_eta)


@pytest.mark.slow
def test_settled_pfcbf_teams_do_not_chatter_in_any_seed():
    """Seeds 0-9, the last 250 of 1000 steps: period-2 turns of ω in at most 10 of the
    15,000 robot-steps, none in vx, vy. Measured: 6 when the bound was set; 81 without the
    FoV lead's hysteresis; 14 on the controller of 8a825c7 (seed 3: 7, a robot pinned by
    its blind rows whose lost FoV rows yielded on alternate steps), 9 with the yield's
    latch (seed 0: 5, one of them a single safe-fallback step; seeds 2 and 9: 2 each).
    With pfcbf's budget leak at 120 s (the creep fix) the courses change: 12 ω flips
    (seed 0: 9, of which robot 1 at steps 940-955: 7; seed 6: 2; seed 3: 1) and one vy
    flip (seed 9). With the hold band that never demands more retreat than the barrier
    (``hold_band_barrier``): 7 / 0 / 11 (vx / vy / ω; seed 5's robot 0 kept right on
    alternate steps); with keep-right's hysteresis (``deadlock_release``) as well:
    0 / 0 / 2 (seeds 2 and 3), and over steps 200-1000 7 / 2 / 32 against 66 / 66 / 139
    before both."""
    from fov_marl.metrics import action_chatter

    total = sum(action_chatter(_pfcbf_actions(seed, 1000)[-250:]) for seed in range(10))
    assert total[0] == total[1] == 0 and total[2] <= 10, total


@pytest.mark.slow
def test_crossing_all_arrive_without_collision_or_ds_violation():
    for seed in range(20):
        rec = run_episode("crossing", "pfcbf", seed, n_agents=4)
        assert rec.arrived == 4 and rec.collisions == 0, (seed, rec)
        assert rec.safety_violations == 0, (seed, rec)


@pytest.mark.slow
def test_crossing_seed_7_stalls_without_lost_fov_yield():
    """The seed the yield fixes is not friendly: without it one robot never arrives (on the
    controller it was found with: before the FoV lead's hysteresis and the fallback's
    changes, each of which lets this seed arrive on its own)."""
    rec = run_episode(
        "crossing", "pfcbf", 7, n_agents=4,
        policy_kwargs={"controller_params": {
            "lost_fov_yield": False, "priority_hysteresis_m": 0.0, **_BEFORE_CONE,
        }},
    )  # fmt: skip
    assert rec.arrived < 4, rec


@pytest.mark.slow
@pytest.mark.parametrize(
    "episode, off",
    [
        # every counterfactual runs on the filter the collision was found with: before the
        # FoV lead's hysteresis (priority_hysteresis_m = 0), which sends these episodes on
        # other courses that stay clear even without the rows
        (
            1,
            {
                "blind_travel_m": 0.0,
                "priority_hysteresis_m": 0.0,
                **_BEFORE_CONE,
                "tracker": _BEFORE_FUSION,
            },
        ),
        # lost_fov_yield and lost_sigma_max_m = 2 (both off in the shipped filter) send
        # this episode on another course; keep them off so the course is the one the
        # rows were built for
        (
            2,
            {
                "last_seen_radius_m": 0.0,
                "blind_travel_m": 0.0,
                "lost_sigma_max_m": math.inf,
                "lost_fov_yield": False,
                "priority_hysteresis_m": 0.0,
                **_BEFORE_CONE,
                # and before the local re-seed of deleted beliefs, which also sends it on
                # another course (0 collisions without the rows; 1, min 0.09 m, with the
                # arena-wide re-seed)
                "tracker": {"recovery_reseed": "arena", **_BEFORE_FUSION},
            },
        ),
    ],
)
def test_filter_regressions_collide_without_the_new_rows(episode, off):
    """The regression episodes above are not friendly: without the rows they collide."""
    assert _stress(episode, **off)["collisions"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("fov_deg, bound", [(120.0, 0.91), (360.0, 0.45)])
def test_filter_random_actions_long_episodes_change_rate_is_reported(fov_deg, bound):
    """Random actions behind the filter, N = 6, 5 episodes x 1000 steps: no collision, and
    the share of changed robot-steps stays below what was measured with the shipped
    filter. At β = 120°: 0.86-0.93, mean 0.895 (``fov-marl evaluate --policy random
    --safety-filter --episodes 5``; 0.83-0.91, mean 0.879, with the option
    ``blind_travel_reach``); 0.86-0.97, mean 0.905, when measured first with the budget
    per bearing, no leak and the glance (0.84-0.88, mean 0.854, with the single vector;
    0.845 with the earlier 1 m budget); 0.69 over 2 x 150 steps. It grows with the time
    the beliefs go unrefreshed.
    At β = 360°: 0.32-0.41, mean 0.386, mostly from the Gaussian half-planes of neighbours
    beyond R_d. The issue's goal of 0.30 is not met. The neighbour rows of diffuse
    beliefs, the blind rows and the blind travel budget do most of it;
    ``lost_sigma_max_m = 2`` gave 0.64-0.73 at 120° but let an adversary collide."""
    rates = []
    for seed in range(5):
        rec = run_episode(
            "coverage", "random", seed, safety_filter=True, n_agents=6, fov_deg=fov_deg
        )
        assert rec.collisions == 0
        rates.append(rec.intervention_rate)
    assert np.mean(rates) < bound, rates


@pytest.mark.parametrize(
    "release, prespend", [("disk", True), ("point", False), ("point", True), ("disk", False)]
)
def test_filter_packed_blind_pair_keeps_its_last_seen_row(release, prespend):
    """Red team 9: head_on, N = 8, β = 45°, clustered start, ``dt_s = 0.4``, 500 particles,
    seed 43600. Robot 7 saw robot 2 (1.45 m away) only at the start; the last-seen point,
    its posterior's mean then, lay 0.75 m off the truth at −6°, inside the 45° view while
    robot 2 stood at −47°. Released as "seen empty" (``last_seen_release="point"``, the
    counterfactual) the row went, and 34 s later robot 7 translated blind into robot 2
    (0.864 m). The filter releases a point only when its whole uncertainty disk is in view
    (``"disk"``, safety Section 2c): no pair comes closer than the start's 1.449 m. The
    bearings robot 7 saw robot 2 at, inside D_s, start spent (``blind_travel_prespend``,
    Section 2g), which keeps the pair clear by itself too, with the point released."""
    from fov_marl.stress import StressCase, run_stress_episode

    case = StressCase(
        "head_on",
        8,
        45.0,
        "clustered",
        env_kwargs={"dt_s": 0.4},
        filter_kwargs={
            "tracker_params": {"n_particles_total": 500},
            # the counterfactual on the filter of then (before blind_travel_reach too)
            "controller_params": {"last_seen_release": release, "blind_travel_prespend": prespend}
            if release == "disk"
            else {
                "last_seen_release": release,
                "blind_travel_reach": False,
                "look_persistence_deg": 0.0,
                "blind_travel_prespend": prespend,
            },
        },
    )
    ep = run_stress_episode(case, 43600, 300)
    if release == "disk" or prespend:
        assert ep["collisions"] == 0 and ep["min_distance_m"] >= 1.44, ep
    else:
        assert ep["collisions"] > 0, ep


@pytest.mark.parametrize("detection_rows", [True, False])
def test_filter_high_detection_noise_small_budget(detection_rows):
    """Red team 9: chase_last_seen, N = 8, β = 360°, wall start, ``meas_cov_diag = (0.5,
    0.5, 1.0)``, ``n_particles_total = 500``, seed 43201. Robot 2 sees robot 1 (1.1 m
    ahead) every step, but its 500-particle posterior drifts through robot 2 itself (mean
    (−0.08, 0) m): the neighbour row's line of sight points backwards, its retreat asks
    for full speed forward, and without the rows on the camera's own report
    (``detection_rows``, safety Section 1d; the counterfactual, a strict xfail of the
    previous release) robot 2 drives into robot 1 (step 175, 0.508 m). With them the
    detection forbids the approach, and no pair comes closer than its 1.1 m start."""
    from fov_marl.stress import StressCase, run_stress_episode

    case = StressCase(
        "chase_last_seen",
        8,
        360.0,
        "wall",
        env_kwargs={"meas_cov_diag": [0.5, 0.5, 1.0]},
        filter_kwargs={
            "tracker_params": {"n_particles_total": 500},
            "controller_params": {"detection_rows": detection_rows}
            if detection_rows
            else {
                "detection_rows": False,
                "blind_travel_reach": False,
                "look_persistence_deg": 0.0,
            },
        },
    )
    ep = run_stress_episode(case, 43201, 300)
    if detection_rows:
        assert ep["collisions"] == 0 and ep["min_distance_m"] >= 1.1 - 1e-6, ep
    else:
        assert ep["collisions"] > 0, ep


@pytest.mark.parametrize("detection_cone", [True, False])
def test_filter_packed_corner_start_holds_its_spacing(detection_cone):
    """Issue 10's grid, β = 360°, N = 24, corner start (a lattice 1.1 m apart, inside D_s),
    seed 60001, any adversary: at step 5 robot 18's posterior of robot 16 (1.1 m away,
    detected, only turning) was 0.70 m and 37° off the truth, outside its 95% ellipse and
    its bearing cone. With the detection's own cone (safety Section 1d,
    ``detection_cone``) the pair keeps the start's spacing; without it (the
    counterfactual) robot 18 in the safe fallback translated at 1 m/s, 6° towards robot
    16, and the pair closed to 1.0963 m (contact at 1.0 m)."""
    from fov_marl.stress import StressCase, run_stress_episode

    case = StressCase(
        "straight",
        24,
        360.0,
        "corner",
        filter_kwargs={"controller_params": {"detection_cone": detection_cone}},
    )
    ep = run_stress_episode(case, 60001, 6)
    assert ep["collisions"] == 0, ep
    if detection_cone:
        assert ep["min_distance_m"] >= 1.1 - 1e-9, ep["min_distance_m"]
    else:
        assert 1.09 < ep["min_distance_m"] < 1.099, ep["min_distance_m"]
