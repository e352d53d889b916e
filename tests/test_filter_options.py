"""``--filter-tracker`` / ``--filter-controller``: the safety filter's options from the CLI.

They reach the filter the episodes run behind (evaluate, render, train and the
evaluation of a model trained behind the filter). Bad values are one-line errors
naming the flag and the field, raised before anything runs.
"""

from __future__ import annotations

import functools
import json

import pytest

import fov_marl.wrappers as wrappers
from fov_marl.cli import main
from fov_marl.evaluation import run_episode
from fov_marl.filter_options import filter_kwargs


@pytest.fixture
def built(monkeypatch):
    """The keywords of every SafetyFilterWrapper built through ``make_env``."""
    seen: list[dict] = []
    base = wrappers.SafetyFilterWrapper

    class Recording(base):  # type: ignore[misc, valid-type]
        @functools.wraps(base.__init__)  # the signature the trainer checks keywords with
        def __init__(self, env, **kw):
            seen.append(kw)
            super().__init__(env, **kw)

    monkeypatch.setattr(wrappers, "SafetyFilterWrapper", Recording)
    return seen


def test_items_become_validated_wrapper_keywords():
    assert filter_kwargs(None, None, True) is None
    assert filter_kwargs(None, None, False) is None
    got = filter_kwargs(
        ["n_particles_total=500", 'motion_model="static"'], ["safety_risk=0.01"], True
    )
    assert got == {
        "tracker_params": {"n_particles_total": 500, "motion_model": "static"},
        "controller_params": {"safety_risk": 0.01},
    }


@pytest.mark.parametrize(
    "tracker, controller, on, words",
    [
        (["n_particles_total=0"], None, True, ["--filter-tracker", "n_particles_total"]),
        (None, ["safety_risk=0.9"], True, ["--filter-controller", "safety_risk", "0.5"]),
        (["bogus=1"], None, True, ["--filter-tracker", "bogus", "n_particles_total"]),
        (None, ["safety_risk"], True, ["--filter-controller", "KEY=VALUE"]),
        (["n_particles_total=500"], None, False, ["--filter-tracker", "--safety-filter"]),
    ],
)
def test_bad_items_name_the_flag_and_the_field(tracker, controller, on, words):
    with pytest.raises(ValueError) as exc:
        filter_kwargs(tracker, controller, on)
    msg = str(exc.value)
    assert all(w in msg for w in words), msg
    assert msg.startswith(words[0])


def test_run_episode_builds_the_filter_with_them():
    seen = []
    run_episode(
        "coverage", "random", 0, safety_filter=True, n_agents=3, max_cycles=3,
        safety_filter_kwargs={"tracker_params": {"n_particles_total": 300}},
        on_step=lambda env, infos: seen.append(env.pipeline.tracker_params.n_particles_total),
    )  # fmt: skip
    assert seen == [300, 300, 300]


def test_cli_evaluate_passes_them_and_matches_the_python_api(tmp_path, built):
    args = ["evaluate", "--policy", "random", "--n-agents", "3", "--episodes", "1",
            "--max-cycles", "20", "--seed", "4", "--safety-filter", "--quiet",
            "--filter-tracker", "n_particles_total=300",
            "--filter-controller", "safety_risk=0.01", "--out", str(tmp_path)]  # fmt: skip
    assert main(args) == 0
    kw = {"tracker_params": {"n_particles_total": 300}, "controller_params": {"safety_risk": 0.01}}
    assert built == [kw]
    ep = json.loads((tmp_path / "results.json").read_text())["episodes"][0]
    ref = run_episode(
        "coverage", "random", 4, safety_filter=True, n_agents=3, max_cycles=20,
        safety_filter_kwargs=kw,
    )  # fmt: skip
    assert ep["final_eta"] == ref.final_eta and ep["min_distance"] == ref.min_distance
    assert ep["filter_interventions"] == ref.filter_interventions


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["evaluate", "--filter-tracker", "n_particles_total=500"], "--filter-tracker"),
        (["evaluate", "--safety-filter", "--filter-controller", "safety_gain=-1"],
         "--filter-controller"),
        (["render", "--safety-filter", "--filter-tracker", "nope=1", "--out", "x.gif"],
         "--filter-tracker"),
        (["train", "--filter-tracker", "n_particles_total=500", "--out", "run"],
         "--filter-tracker"),
    ],
)  # fmt: skip
def test_cli_errors_are_one_line_naming_the_flag(argv, flag, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main([*argv, "--episodes", "1"] if argv[0] == "evaluate" else argv))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert flag in err and len(err.splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "run").exists()  # refused before anything ran


def test_train_stores_them_and_evaluation_reuses_them(tmp_path, built):
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "run"
    code = main(
        ["train", "--safety-filter", "--filter-tracker", "n_particles_total=200",
         "--timesteps", "64", "--n-envs", "1", "--n-agents", "2", "--train-max-cycles", "16",
         "--out", str(out), "--no-progress", "--checkpoint-every", "0",
         "--hp", "n_steps=16", "--hp", "batch_size=32", "--hp", "n_epochs=1"]
    )  # fmt: skip
    assert code in (0, None) or str(code).endswith("model.zip")
    kw = {"tracker_params": {"n_particles_total": 200}}
    assert json.loads((out / "config.json").read_text())["safety_filter_kwargs"] == kw
    built.clear()
    # the model was trained behind the filter: it is evaluated behind the same one
    assert main(["evaluate", "--policy", str(out), "--episodes", "1", "--max-cycles", "4",
                 "--quiet"]) == 0  # fmt: skip
    assert built == [kw]
    built.clear()
    assert main(["evaluate", "--policy", str(out), "--episodes", "1", "--max-cycles", "4",
                 "--quiet", "--filter-tracker", "n_particles_total=400"]) == 0  # fmt: skip
    assert built == [{"tracker_params": {"n_particles_total": 400}}]


def test_cli_stress_runs_its_cases_behind_the_options(tmp_path, built):
    out = tmp_path / "rows.json"
    args = ["stress", "--adversaries", "head_on", "--n-agents", "2", "--fov-deg", "120",
            "--starts", "head_on_pair", "--episodes", "1", "--steps", "5", "--quiet",
            "--filter-tracker", "n_particles_total=300", "--json", str(out)]  # fmt: skip
    assert main(args) == 0
    kw = {"tracker_params": {"n_particles_total": 300}}
    assert built == [kw]
    assert json.loads(out.read_text())["rows"][0]["filter_kwargs"] == kw


def test_cli_stress_unfiltered_refuses_them(capsys):
    code = main(["stress", "--no-filter", "--filter-controller", "safety_risk=0.01", "--quick"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "--filter-controller" in err and "--no-filter" in err and len(err.splitlines()) == 1


def test_filter_init_reaches_the_filter_of_evaluate_and_stress(tmp_path, built):
    """``--filter-init uniform``: the filter starts without the team's start poses."""
    assert filter_kwargs(None, None, True, init="uniform") == {"init": "uniform"}
    assert filter_kwargs(["n_particles_total=300"], None, True, init="known") == {
        "tracker_params": {"n_particles_total": 300},
        "init": "known",
    }
    with pytest.raises(ValueError, match="--filter-init.*--safety-filter"):
        filter_kwargs(None, None, False, init="uniform")
    with pytest.raises(ValueError, match="--filter-init must be one of"):
        filter_kwargs(None, None, True, init="nearby")
    assert main(["evaluate", "--policy", "random", "--safety-filter", "--n-agents", "2",
                 "--episodes", "1", "--max-cycles", "3", "--quiet",
                 "--filter-init", "uniform"]) == 0  # fmt: skip
    args = ["stress", "--adversaries", "straight", "--n-agents", "2", "--fov-deg", "120",
            "--starts", "wall", "--episodes", "1", "--steps", "3", "--quiet",
            "--filter-init", "uniform", "--json", str(tmp_path / "rows.json")]  # fmt: skip
    assert main(args) == 0
    assert built == [{"init": "uniform"}, {"init": "uniform"}]


def test_cli_filter_init_errors_are_one_line(capsys):
    assert main(["evaluate", "--filter-init", "uniform", "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--filter-init" in err and "--safety-filter" in err and len(err.splitlines()) == 1
    assert main(["stress", "--no-filter", "--filter-init", "uniform", "--quick"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--filter-init" in err and "--no-filter" in err and len(err.splitlines()) == 1


def test_stress_table_names_a_uniform_filter_init():
    from fov_marl.stress import format_stress_table

    row = {"adversary": "straight", "n_agents": 2, "fov_deg": 120.0, "start": "wall",
           "filtered": True, "episodes": 1, "collisions": 0}  # fmt: skip
    uni = format_stress_table([{**row, "filter_kwargs": {"init": "uniform"}}])
    assert "uniform" in uni.splitlines()[2]
    assert " yes " in format_stress_table([row]).splitlines()[2]
    assert " no " in format_stress_table([{**row, "filtered": False}]).splitlines()[2]


def test_filter_threads_flag(tmp_path, capsys):
    """``--filter-threads T`` (train): the wrappers' ``tracker_threads``, checked first."""
    assert filter_kwargs(None, None, True, threads="2") == {"tracker_threads": 2}
    assert filter_kwargs(["n_particles_total=300"], None, True, threads=1) == {
        "tracker_params": {"n_particles_total": 300},
        "tracker_threads": 1,
    }
    for bad in ("0", "1025", "1.5", "-1", "two", "", "²", "١"):
        with pytest.raises(ValueError, match=r"--filter-threads must be an integer in \[1, 1024\]"):
            filter_kwargs(None, None, True, threads=bad)
    with pytest.raises(ValueError, match="--filter-threads.*--safety-filter"):
        filter_kwargs(None, None, False, threads="2")
    out = tmp_path / "run"
    assert main(["train", "--safety-filter", "--filter-threads", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--filter-threads" in err and "[1, 1024]" in err and len(err.splitlines()) == 1
    assert not out.exists()
    # evaluate has no such flag (one team's filters gain nothing from threads)
    with pytest.raises(SystemExit):
        main(["evaluate", "--safety-filter", "--filter-threads", "2", "--episodes", "1"])
