"""The TorchRL and BenchMARL example scripts run (in-process, tiny budgets)."""

from __future__ import annotations

import importlib.util
from importlib.util import find_spec
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
README = EXAMPLES.parent / "README.md"  # an existing file


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(find_spec("torchrl") is None, reason="needs torchrl")
def test_torchrl_rollout_example(capsys):
    out = _load("torchrl_rollout").main(["--n-agents=4", "--steps=12", "--safety-filter"])
    assert out["steps"] == 12 and out["observation_shape"] == [12, 4, 5 * 3 + 7]
    assert out["action_shape"] == [12, 4, 3] and 0.0 <= out["final_eta"] <= 1.0
    assert 0.0 <= out["intervention_rate"] <= 1.0
    assert '"final_eta"' in capsys.readouterr().out.splitlines()[-1]


@pytest.mark.skipif(find_spec("benchmarl") is None, reason="needs benchmarl")
def test_benchmarl_example(tmp_path):
    out = _load("benchmarl_mappo").main(
        ["--iterations=1", "--frames=40", "--max-cycles=20", "--n-agents=3", f"--out={tmp_path}"]
    )
    assert out["iterations"] == 1 and out["frames"] == 40
    assert any(Path(out["folder"]).rglob("collection_fov_final_eta.csv"))


@pytest.mark.parametrize(
    ("name", "argv", "message"),
    [
        ("torchrl_rollout", ["--steps=0"], "--steps must be an integer in [1, inf)"),
        ("torchrl_rollout", ["--n-agents=0"], "n_agents"),
        ("benchmarl_mappo", ["--algorithm=dqn"], "algorithm must be one of"),
        ("benchmarl_mappo", ["--frames=0"], "--frames must be an integer in [1, inf)"),
        # an existing file as --out: a FileExistsError traceback (RLlib's only after the
        # whole training, when the checkpoint was written); a negative CPU count: Ray's
        ("benchmarl_mappo", [f"--out={README}"], "is a file, not a folder"),
        ("rllib_ppo", [f"--out={README}"], "is a file, not a folder"),
        ("rllib_ppo", [f"--out={README / 'run'}"], "is a file, not a folder"),
        ("benchmarl_mappo", [f"--out={README / 'run'}"], "README.md/run"),
        ("rllib_ppo", ["--num-cpus=-1"], "--num-cpus must be an integer in [1, inf)"),
    ],
)
def test_examples_reject_bad_arguments_in_one_line(name, argv, message):
    framework = {"torchrl": "torchrl", "benchmarl": "benchmarl", "rllib": "ray"}
    if find_spec(framework[name.split("_")[0]]) is None:
        pytest.skip("framework not installed")
    with pytest.raises(SystemExit) as exc:
        _load(name).main(argv)
    text = str(exc.value)
    assert text.startswith(f"{name}.py: error: ") and message in text and "\n" not in text
