"""BenchMARL: the shipped tasks build Experiments for MAPPO, IPPO and MASAC and run."""

from __future__ import annotations

import pickle
import sys
import time
from importlib.util import find_spec

import pytest

from fov_marl.integrations.benchmarl import make_experiment

# find_spec, not importorskip: importing benchmarl (torch, torchrl) at collection would
# cost every xdist worker; the tests import FovMarlTask (which imports benchmarl) lazily
pytestmark = pytest.mark.skipif(find_spec("benchmarl") is None, reason="needs benchmarl")


def _tasks():
    from fov_marl.integrations.benchmarl import FovMarlTask

    return FovMarlTask


TINY = {
    "max_n_iters": 1,
    "evaluation": False,
    "on_policy_collected_frames_per_batch": 40,
    "on_policy_n_envs_per_worker": 2,
    "on_policy_minibatch_size": 20,
    "on_policy_n_minibatch_iters": 1,
    "off_policy_collected_frames_per_batch": 40,
    "off_policy_n_envs_per_worker": 2,
    "off_policy_n_optimizer_steps": 2,
    "off_policy_train_batch_size": 16,
    "off_policy_memory_size": 1000,
}


@pytest.mark.parametrize("algorithm", ["mappo", "ippo", "masac"])
def test_one_iteration_of_each_algorithm(algorithm, tmp_path):
    tv_before = "torchvision" in sys.modules
    task = _tasks().COVERAGE.get_task({"n_agents": 3, "max_cycles": 20})
    exp = make_experiment(algorithm, task, seed=0, save_folder=str(tmp_path), **TINY)
    assert exp.group_map == {"robot": ["robot_0", "robot_1", "robot_2"]}
    assert exp.max_steps == 20 and exp.continuous_actions
    exp.run()
    assert exp.n_iters_performed == 1 and exp.total_frames == 40
    if not tv_before:  # the BenchMARL path never imports torchvision (broken beside CPU torch)
        assert "torchvision" not in sys.modules


def test_safety_filter_and_crossing_tasks_run(tmp_path):
    task = _tasks().COVERAGE.get_task(
        {
            "n_agents": 3,
            "max_cycles": 10,
            "safety_filter": True,
            "filter_kwargs": {"tracker_params": {"n_particles_total": 300}},
        }
    )
    exp = make_experiment("mappo", task, save_folder=str(tmp_path), **TINY)
    assert "safety/status_code" in exp.info_spec["robot", "info"].keys()
    exp.run()
    task = _tasks().CROSSING.get_task({"max_cycles": 10})
    exp = make_experiment("ippo", task, save_folder=str(tmp_path), **TINY)
    exp.run()
    assert exp.total_frames == 40 and len(exp.group_map["robot"]) == 4


def test_log_info_reports_episode_end_metrics():
    from fov_marl.integrations.torchrl import make_env

    env = make_env(n_agents=3, max_cycles=5, seed=0)
    batch = env.rollout(10, break_when_any_done=False)
    out = _tasks().COVERAGE.get_task({}).log_info(batch)
    eta = batch["next", "robot", "info", "metrics/eta"][[4, 9], 0].mean().item()
    assert out["collection/fov/final_eta"] == pytest.approx(eta)
    assert "collection/fov/final_collisions_total" in out
    assert _tasks().COVERAGE.get_task({}).log_info(batch[:3]) == {}


def test_defaults_registry_pickling_and_errors():
    from benchmarl.environments import task_config_registry, tasks

    task = _tasks().COVERAGE.get_from_yaml()
    assert task.config == {} and task.max_steps(None) == 1000  # the paper's defaults
    assert task_config_registry["fov_marl/coverage"] is _tasks().COVERAGE
    assert task_config_registry["fov_marl/crossing"] is _tasks().CROSSING
    assert _tasks() in tasks
    clone = pickle.loads(pickle.dumps(task))  # BenchMARL pickles the task into config.pkl
    assert clone == task and clone.scenario_config == task.scenario_config
    with pytest.raises(ValueError, match="fov_deg"):
        _tasks().COVERAGE.get_task({"fov_deg": -5.0})
    with pytest.raises(ValueError, match="unknown"):
        _tasks().COVERAGE.get_task({"n_robots": 3})
    with pytest.raises(ValueError, match="safety_filter must be True or False"):
        _tasks().COVERAGE.get_task({"safety_filter": "yes"})
    with pytest.raises(ValueError, match="continuous actions only"):
        task.get_env_fun(1, False, 0, "cpu")
    with pytest.raises(ValueError, match=r"algorithm must be one of \['mappo'"):
        make_experiment("dqn")
    with pytest.raises(ValueError, match="experiment_overrides: unknown field 'max_iters'"):
        make_experiment("mappo", task, max_iters=3)


@pytest.mark.slow
def test_mappo_trains_a_few_iterations(tmp_path):
    """5 MAPPO iterations x 1,200 frames on N = 4 (time printed for the closing note)."""
    task = _tasks().COVERAGE.get_task({"n_agents": 4, "max_cycles": 100})
    exp = make_experiment(
        "mappo",
        task,
        save_folder=str(tmp_path),
        max_n_iters=5,
        evaluation=False,
        on_policy_collected_frames_per_batch=1200,
        on_policy_n_envs_per_worker=4,
        on_policy_minibatch_size=300,
        on_policy_n_minibatch_iters=4,
    )
    t0 = time.perf_counter()
    exp.run()
    wall = time.perf_counter() - t0
    print(f"benchmarl mappo: 5 iterations x 1200 frames in {wall:.1f} s")
    assert exp.n_iters_performed == 5 and exp.total_frames == 6000


def test_serial_training_env_copies_start_from_different_seeds():
    """Copy k of the SerialEnv BenchMARL builds starts from seed + k (it was every copy
    from seed: all copies started every episode from one configuration)."""
    import torch
    from torchrl.envs import SerialEnv

    task = _tasks().COVERAGE.get_task({"n_agents": 3, "max_cycles": 4})
    env = SerialEnv(3, task.get_env_fun(num_envs=3, continuous_actions=True, seed=5, device="cpu"))
    try:
        st = env.reset()["state"]
        assert not torch.equal(st[0], st[1]) and not torch.equal(st[1], st[2])
        # each copy is an env the factory seeded with 5 + k (SerialEnv may build one more
        # env for its specs first, so the copies' k need not start at 0)
        starts = []
        for k in range(5):
            fn = task.get_env_fun(num_envs=1, continuous_actions=True, seed=5 + k, device="cpu")
            one = fn()
            starts.append(one.reset()["state"])
            one.close()
        for c in range(3):
            assert any(torch.equal(st[c], x) for x in starts)
    finally:
        env.close()


def test_parallel_collector_workers_start_from_distinct_reproducible_seeds():
    """Red team 6: in a ParallelEnv each worker got a pickled factory counting from 0, so
    every copy started every episode from ``seed``. Workers now mix in their process
    identity: copies differ, and the same script gives the same starts."""
    import subprocess

    script = (
        "import torch\n"
        "from torchrl.envs import ParallelEnv\n"
        "from fov_marl.integrations.benchmarl import FovMarlTask\n"
        "if __name__ == '__main__':\n"
        "    t = FovMarlTask.COVERAGE.get_task({'n_agents': 2, 'max_cycles': 5})\n"
        "    p = ParallelEnv(2, t.get_env_fun(2, True, 7, 'cpu'))\n"
        "    s = p.reset()['state']\n"
        "    print(not torch.equal(s[0], s[1]), s.sum(-1).tolist())\n"
        "    p.close()\n"
    )
    runs = [
        subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=240)
        .stdout.strip()
        .splitlines()[-1]
        for _ in range(2)
    ]
    assert runs[0].startswith("True ") and runs[0] == runs[1], runs


def test_copy_seed_is_seed_plus_k_in_the_factorys_process():
    import os

    from fov_marl.integrations._benchmarl_tasks import copy_seed

    assert copy_seed(7, 3, os.getpid()) == 10
    other = [copy_seed(7, k, -1) for k in range(3)]  # "another process": drawn, distinct
    assert len(set(other)) == 3 and all(0 <= s < 2**31 for s in other)


def test_task_config_changes_and_bad_task_inputs(tmp_path):
    """Red team 6: max_steps kept the max_cycles of construction after
    ``task.config.update`` (BenchMARL's way to change a task); bad task configs, YAML
    files, task names, seeds and batch sizes were TypeError / AttributeError /
    ZeroDivisionError."""
    task = _tasks().COVERAGE.get_task({"n_agents": 2})
    task.config.update({"max_cycles": 7})
    assert task.max_steps(None) == 7
    env = task.get_env_fun(1, True, 0, "cpu")()
    assert env.rollout(50).shape[0] == 7
    env.close()
    task.config.update({"fov_deg": 500.0})
    with pytest.raises(ValueError, match="fov_deg"):  # checked when the envs are made
        task.get_env_fun(1, True, 0, "cpu")
    with pytest.raises(ValueError, match=r"scenario is fixed by the task.*FovMarlTask.CROSSING"):
        _tasks().COVERAGE.get_task({"scenario": "crossing"})
    for bad in ([1, 2], "n_agents=3"):
        with pytest.raises(ValueError, match="task config must be a dict"):
            _tasks().COVERAGE.get_task(bad)
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="must be a mapping"):
        _tasks().COVERAGE.get_from_yaml(str(listed))
    with pytest.raises(ValueError, match=r"task must be one of \['fov_marl/coverage'"):
        make_experiment("mappo", "fov_marl/nope")
    with pytest.raises(ValueError, match="task must be None, a FovMarlTask"):
        make_experiment("mappo", 3)
    with pytest.raises(ValueError, match="seed must be an integer"):
        make_experiment("mappo", seed="x")
    with pytest.raises(ValueError, match="on_policy_collected_frames_per_batch"):
        make_experiment("mappo", on_policy_collected_frames_per_batch=0)
    exp = make_experiment("mappo", "fov_marl/crossing", save_folder=str(tmp_path), **TINY)
    assert exp.task.scenario == "crossing"


_BAD_OVERRIDES = [
    (
        {"max_n_iters": -1},
        r"experiment_overrides\['max_n_iters'\] must be an integer in \[1, inf\) \(or None\), got -1",
    ),
    ({"max_n_iters": 0}, r"'max_n_iters'\] must be an integer in \[1, inf\)"),
    ({"max_n_frames": -5}, r"'max_n_frames'\] must be an integer in \[1, inf\)"),
    ({"max_n_iters": "a"}, r"'max_n_iters'\] must be an integer .*got 'a' \(str\)"),
    ({"max_n_iters": 2.0}, r"'max_n_iters'\] must be an integer"),
    ({"max_n_iters": None}, "max_n_iters and max_n_frames are both None"),
    ({"lr": "abc"}, r"'lr'\] must be a real number in \(0.0, inf\), got 'abc'"),
    ({"lr": 0.0}, r"'lr'\] must be in \(0.0, inf\)"),
    ({"gamma": float("nan")}, r"'gamma'\] must be finite"),
    ({"evaluation": 1}, r"'evaluation'\] must be a bool"),
    ({"loggers": "csv"}, r"'loggers'\] must be a list of str"),
    (
        {"algorithm_overrides": {"clip_epsilon": "x"}},
        r"algorithm_overrides\['clip_epsilon'\] must be a real number in \[0.0, 1.0\]",
    ),
    ({"algorithm_overrides": {"lmbda": 2}}, r"'lmbda'\] must be in \[0.0, 1.0\]"),
    (
        {"algorithm_overrides": {"share_param_critic": "yes"}},
        r"'share_param_critic'\] must be a bool",
    ),
    (
        {"algorithm_overrides": [1]},
        r"algorithm_overrides must be a dict of MappoConfig fields or None, got \[1\] \(list\)",
    ),
    ({"save_folder": 5}, "save_folder must be a directory path, got 5"),
    ({"save_folder": "/nonexistent/fov"}, "save_folder /nonexistent/fov: no such directory"),
]


@pytest.mark.parametrize(
    ("kwargs", "says"), _BAD_OVERRIDES, ids=[repr(k) for k, _ in _BAD_OVERRIDES]
)
def test_make_experiment_checks_override_types_and_ranges(kwargs, says):
    """Red team 7: negative or zero budgets ran 0 iterations silently; strings, lists and
    non-dict overrides gave TypeError / AttributeError from BenchMARL or torch."""
    with pytest.raises(ValueError, match=says):
        make_experiment("mappo", **kwargs)


def test_make_experiment_override_types_come_from_benchmarls_annotations(tmp_path):
    import numpy as np

    with pytest.raises(ValueError, match=r"'target_entropy'\] must be a real number or a string"):
        make_experiment("masac", algorithm_overrides={"target_entropy": [1]})
    with pytest.raises(ValueError, match=r"'min_alpha'\] must be in \[0.0, inf\) \(or None\)"):
        make_experiment("masac", algorithm_overrides={"min_alpha": -1.0})
    tiny = {**TINY, "max_n_iters": np.int64(1), "lr": 1}  # NumPy ints and ints are fine
    exp = make_experiment(
        "masac",
        save_folder=str(tmp_path),
        algorithm_overrides={"target_entropy": -2, "min_alpha": None},
        **tiny,
    )
    assert exp.config.max_n_iters == 1 and type(exp.config.max_n_iters) is int
    assert exp.config.lr == 1.0 and exp.algorithm_config.target_entropy == -2.0
