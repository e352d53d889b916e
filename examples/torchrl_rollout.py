"""Roll out fov_coverage_v0 as a TorchRL environment and print what the tensors hold.

Run (with the ``[torchrl]`` extra)::

    python examples/torchrl_rollout.py                  # N = 6, 100 random-action steps
    python examples/torchrl_rollout.py --safety-filter --steps 50

Builds the env with :func:`fov_marl.integrations.torchrl.make_env`, checks its specs
with TorchRL's ``check_env_specs``, rolls out uniform random actions and prints the
tensor shapes, the final coverage efficiency η and, behind the safety filter, the
fraction of robot-steps the filter changed. Ends with a JSON summary line.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n-agents", type=int, default=6, help="robots (default 6)")
    p.add_argument("--steps", type=int, default=100, help="rollout steps (default 100)")
    p.add_argument("--safety-filter", action="store_true", help="wrap in the safety filter")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    args = p.parse_args(argv)
    if args.steps < 1:
        sys.exit("torchrl_rollout.py: error: --steps must be an integer in [1, inf)")

    from fov_marl.integrations.torchrl import GROUP, make_env

    try:
        env = make_env(n_agents=args.n_agents, safety_filter=args.safety_filter, seed=args.seed)
    except ValueError as exc:
        sys.exit(f"torchrl_rollout.py: error: {exc}")
    from torchrl.envs.utils import check_env_specs

    check_env_specs(env, seed=args.seed)
    td = env.rollout(args.steps, break_when_any_done=False)
    info = td["next", GROUP, "info"]
    summary: dict[str, Any] = {
        "steps": int(td.batch_size[0]),
        "observation_shape": list(td["next", GROUP, "observation"].shape),
        "action_shape": list(td[GROUP, "action"].shape),
        "state_shape": list(td["next", "state"].shape),
        "final_eta": round(float(info["metrics/eta"][-1, 0]), 4),
        "collisions_total": int(info["metrics/collisions_total"][-1, 0]),
    }
    if args.safety_filter:
        summary["intervention_rate"] = round(float(info["safety/intervened"].mean()), 4)
    for k, v in summary.items():
        print(f"{k:>18}: {v}")
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
