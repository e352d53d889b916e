"""``fov-marl train``: options of a wrapper need the flag that turns the wrapper on.

``--belief-init`` without ``--belief`` is refused in one line naming both flags, before
anything is written (as ``--filter-threads`` without ``--safety-filter`` is), and the
value given with ``--belief`` reaches the belief wrapper.
"""

from __future__ import annotations

import argparse

import pytest

pytest.importorskip("stable_baselines3")

from fov_marl.cli import main  # noqa: E402
from fov_marl.training.cli_support import add_train_arguments, run_train  # noqa: E402

TINY = ["--n-agents", "2", "--n-envs", "1", "--timesteps", "8", "--no-progress"]


class _Stop(Exception):
    """Raised by the stand-in for ``train``: the run got as far as training."""


@pytest.fixture
def train_kwargs(monkeypatch):
    """The keywords ``run_train`` passes to ``train`` (which is not run)."""
    import fov_marl.training.trainer as trainer

    seen: dict = {}

    def fake_train(*args, **kwargs):
        seen.update(kwargs)
        raise _Stop

    monkeypatch.setattr(trainer, "train", fake_train)
    return seen


def _run_train(argv: list[str]) -> None:
    parser = argparse.ArgumentParser()
    add_train_arguments(parser)
    run_train(parser.parse_args(argv))


@pytest.mark.parametrize("init", ["uniform", "known"])
def test_belief_init_without_belief_is_refused_naming_both_flags(tmp_path, capsys, init):
    out = tmp_path / "run"
    assert main(["train", *TINY, "--belief-init", init, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--belief-init" in err and "add --belief" in err
    assert not out.exists()  # refused before anything was written


def test_belief_init_without_belief_is_refused_before_training(tmp_path, train_kwargs):
    with pytest.raises(ValueError, match=r"^--belief-init .*: add --belief$"):
        _run_train([*TINY, "--belief-init", "uniform", "--out", str(tmp_path / "r")])
    assert train_kwargs == {}


@pytest.mark.parametrize(
    "extra, belief_kwargs",
    [
        (["--belief", "--belief-init", "uniform"], {"init": "uniform"}),
        (["--belief", "--belief-init", "known"], {"init": "known"}),
        (["--belief"], {"init": "known"}),  # the default
        ([], None),
    ],
)
def test_belief_init_reaches_the_belief_wrapper(tmp_path, train_kwargs, extra, belief_kwargs):
    with pytest.raises(_Stop):
        _run_train([*TINY, *extra, "--out", str(tmp_path / "r")])
    assert train_kwargs["belief"] is bool(extra)
    assert train_kwargs["belief_kwargs"] == belief_kwargs


def test_belief_init_help_says_it_needs_belief(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--belief-init {known,uniform} with --belief:" in help_text
