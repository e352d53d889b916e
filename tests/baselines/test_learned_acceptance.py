"""Acceptance of the shipped learned policy (issue 14), against pfcbf on the same seeds.

Slow (``pytest -m slow tests/baselines/test_learned_acceptance.py``: ~15 min on 2 cores).
The learned policy runs behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`
(``safety_filter=True``); pfcbf is the paper's controller as it is (its CBF is built in).
The measured numbers are in the README ("Learned policy").
"""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.evaluation import run_episode

pytestmark = pytest.mark.slow

SEEDS = list(range(20))


def _runs(policy: str, n_agents: int, seeds: list[int], safety_filter: bool) -> list:
    return [
        run_episode(
            "coverage", policy, s, safety_filter=safety_filter, n_agents=n_agents, fov_deg=120.0
        )
        for s in seeds
    ]


@pytest.fixture(scope="module")
def n6() -> tuple[list, list]:
    return _runs("learned", 6, SEEDS, True), _runs("pfcbf", 6, SEEDS, False)


def test_n6_behind_the_filter_no_collision(n6):
    learned, _ = n6
    assert sum(r.collisions for r in learned) == 0


def test_n6_final_eta_above_pfcbf_paired(n6):
    learned, pfcbf = n6
    d = np.array([a.final_eta - b.final_eta for a, b in zip(learned, pfcbf, strict=True)])
    print(f"final eta learned - pfcbf: mean {d.mean():+.5f}, {np.sum(d > 0)}/{len(d)} seeds above")
    assert d.mean() > 0.0


def test_n6_time_to_normalised_threshold_not_longer_than_pfcbf(n6):
    learned, pfcbf = n6
    t_l = np.array(
        [np.inf if r.time_to_eta_norm_s is None else r.time_to_eta_norm_s for r in learned]
    )
    t_p = np.array(
        [np.inf if r.time_to_eta_norm_s is None else r.time_to_eta_norm_s for r in pfcbf]
    )
    print(f"time to 0.95 eta_opt: learned {t_l.mean():.2f} s, pfcbf {t_p.mean():.2f} s")
    assert np.all(np.isfinite(t_l))
    assert t_l.mean() <= t_p.mean()


def test_n6_intervention_rate_goal(n6):
    learned, _ = n6
    rate = float(np.mean([r.intervention_rate for r in learned]))
    print(f"filter intervention rate on the learned policy: {rate:.3f}")
    assert rate <= 0.10


@pytest.mark.parametrize("n_agents", [4, 8, 10, 12])
def test_same_weights_other_team_sizes_no_collision(n_agents):
    seeds = SEEDS[:5]
    learned = _runs("learned", n_agents, seeds, True)
    pfcbf = _runs("pfcbf", n_agents, seeds, False)
    eta_l = np.mean([r.final_eta for r in learned])
    eta_p = np.mean([r.final_eta for r in pfcbf])
    print(f"N={n_agents}: final eta learned+filter {eta_l:.4f}, pfcbf {eta_p:.4f}")
    assert sum(r.collisions for r in learned) == 0
