"""Save a scenario config as JSON, read it back, and use it from Python and the CLI.

    python examples/config_file.py

``ScenarioConfig.to_dict`` / ``from_dict`` round-trip exactly; the same file works as
``fov-marl evaluate --config scenario.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

from _common import steps

from fov_marl.cli import main as fov_marl
from fov_marl.config import ScenarioConfig, make_config
from fov_marl.envs import fov_coverage_v0


def main() -> None:
    cfg = make_config(n_agents=4, fov_deg=90.0, density_sigma_m=4.0, max_cycles=steps(200))
    path = Path("scenario.json")
    path.write_text(json.dumps(cfg.to_dict(), indent=2))
    back = ScenarioConfig.from_dict(json.loads(path.read_text()))
    assert back == cfg
    kw = {k: v for k, v in back.to_dict().items() if k not in ("scenario", "initial_poses")}
    env = fov_coverage_v0.parallel_env(**kw)
    obs, _ = env.reset(seed=0)
    print(f"{len(obs)} robots, observation size {next(iter(obs.values())).shape[0]}")
    env.close()
    fov_marl(["evaluate", "--config", str(path), "--policy", "pfcbf", "--episodes", "1",
              "--quiet"])  # fmt: skip


if __name__ == "__main__":
    main()
