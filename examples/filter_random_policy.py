"""Make a random policy safe with SafetyFilterWrapper and count what it prevented.

    python examples/filter_random_policy.py

The same seeded random actions drive a team without and with the filter; the filter
changes an action only when a CBF row would be violated (``safety_of(infos[a])``).
"""

from __future__ import annotations

from _common import steps

from fov_marl.baselines import make_policy
from fov_marl.envs import fov_coverage_v0
from fov_marl.infos import metrics_of, safety_of
from fov_marl.wrappers import SafetyFilterWrapper


def run(filtered: bool, seed: int = 0) -> dict:
    env = fov_coverage_v0.parallel_env(n_agents=6, fov_deg=120.0, max_cycles=steps(300))
    if filtered:
        env = SafetyFilterWrapper(env)
    policy = make_policy("random", env)
    obs, infos = env.reset(seed=seed)
    policy.reset(seed=seed)
    interventions = 0
    while env.agents:
        obs, _, _, _, infos = env.step(policy.act(obs))
        if filtered:
            interventions += sum(bool(safety_of(infos[a])["intervened"]) for a in infos)
    metrics = metrics_of(next(iter(infos.values())))
    env.close()
    return {
        "collisions": int(metrics["collisions_total"]),
        "min_distance_m": float(metrics["min_distance_episode"]),
        "interventions": interventions,
    }


def main() -> None:
    raw, safe = run(False), run(True)
    print(f"random policy:           {raw}")
    print(f"behind the safety filter: {safe}")


if __name__ == "__main__":
    main()
