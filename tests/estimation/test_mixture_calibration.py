"""The default tracker (the mode mixture) stays calibrated whatever the neighbours do.

For every behaviour of :mod:`tests.estimation.behaviours` (pfcbf, uniform random, smooth
random, and the adversaries straight / charge the centre / spin while charging / chase /
wait then charge), every robot of a team of 6 is driven by it and a bank of all robots'
default trackers counts how often the truth is inside the reported 95% ellipse, pooled over
every (robot, neighbour) pair and step. Asserted: ``0.90 <= rate <= 0.98`` (issue 10,
item 8), and that the ellipses stay useful where they can be: mean semi-major axis below
1 m for detected neighbours and below 5 m for those unseen for less than 5 s (an ellipse
covering the arena is "calibrated" and useless). ``pytest -s`` prints the table with
the mean semi-major axis of every category: long-unseen neighbours get large ellipses
(e.g. robots parked in corners, facing the walls, that nobody saw go there).

The normal suite runs 3 seeds x 300 steps (60 s, the episode length of the issue's
adversarial sweep) per behaviour, for the default tracker (P_T = 2000) and for the
safety filter's (``FILTER_TRACKER_DEFAULTS``: measured 0.938-0.975), at P_T = 2000 and at
its reduced budget P_T = 500 (``fov_marl.bench.FAST_FILTER_PARTICLES``; measured
0.904-0.955 with the fused recovery, 0.926-0.954 with the re-seed; at P_T = 250
``straight`` fell to 0.894); the ``slow`` test 10 other seeds, at N = 6 and 12.
Longer episodes drift up (more of the steps are long-unseen neighbours, which are
over-covered): at 6 x 600 steps, N = 6, the rates were 0.919 (straight) to 0.978.
"""

from __future__ import annotations

import pytest

from fov_marl.estimation import TrackerParams

from .behaviours import BEHAVIOURS, pooled

LO, HI = 0.90, 0.98


def _show(name, st, tag):
    cats = " ".join(
        f"{k} {v['rate']:.3f} (n={v['n']}, a={v['mean_a_m']:.1f} m)" for k, v in st.items()
    )
    print(f"\n[mixture calibration {tag}] {name:14s} {cats}")


def _check(name, st):
    rate = st["all"]["rate"]
    assert LO <= rate <= HI, f"{name}: truth inside the 95% ellipse in {rate:.3f} of the steps"
    # usefulness: tight where the camera sees, modest just after it lost sight
    for cat, bound in (("detected", 1.0), ("recent", 5.0)):
        a = st[cat]["mean_a_m"]
        assert a < bound, f"{name}: mean semi-major axis {a:.2f} m of {cat} neighbours"


@pytest.mark.parametrize("name", BEHAVIOURS)
def test_default_model_is_calibrated(name):
    st = pooled(name, TrackerParams(), steps=300, seeds=(0, 1, 2))
    _show(name, st, "3 x 300")
    _check(name, st)


@pytest.mark.parametrize("name", BEHAVIOURS)
def test_filter_tracker_is_calibrated(name):
    # the safety filter's tracker (FILTER_TRACKER_DEFAULTS: the bias test and the fused
    # recovery of collapsed clouds on top of the mixture); measured 0.938-0.975
    from fov_marl.wrappers.safety_filter import FILTER_TRACKER_DEFAULTS

    st = pooled(name, TrackerParams(**FILTER_TRACKER_DEFAULTS), steps=300, seeds=(0, 1, 2))
    _show(name, st, "filter 3 x 300")
    _check(name, st)


@pytest.mark.parametrize("name", BEHAVIOURS)
def test_reduced_budget_is_calibrated(name):
    # the filter's tracker at its reduced particle budget (fov_marl.bench.
    # FAST_FILTER_PARTICLES, the budget at which the batched filter is timed for issue
    # 12): same bounds; measured 0.904-0.955
    from fov_marl.bench import FAST_FILTER_PARTICLES
    from fov_marl.wrappers.safety_filter import FILTER_TRACKER_DEFAULTS

    params = TrackerParams(
        **{**FILTER_TRACKER_DEFAULTS, "n_particles_total": FAST_FILTER_PARTICLES}
    )
    st = pooled(name, params, steps=300, seeds=(0, 1, 2))
    _show(name, st, f"P_T={FAST_FILTER_PARTICLES} 3 x 300")
    _check(name, st)


@pytest.mark.slow
@pytest.mark.parametrize("n_agents", [6, 12])
@pytest.mark.parametrize("name", BEHAVIOURS)
def test_default_model_is_calibrated_long(name, n_agents):
    st = pooled(name, TrackerParams(), steps=300, seeds=range(10, 20), n_agents=n_agents)
    _show(name, st, f"N={n_agents} 10 x 300")
    _check(name, st)
