"""Red team 8 (F16): register_policy checks its arguments before the registry changes,
so a bad registration cannot break available_policies() or make_policy() for others."""

from __future__ import annotations

import pytest

from fov_marl.baselines import available_policies, make_policy, register_policy, registry
from fov_marl.envs import fov_coverage_v0


@pytest.fixture(autouse=True)
def _private_registry(monkeypatch):
    """Registrations made here do not outlive the test."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_OPTIONS", dict(registry._OPTIONS))


@pytest.mark.parametrize("name", [123, None, "", "   ", ("a",), b"x"])
def test_a_name_that_is_not_a_non_empty_string_is_refused(name):
    before = available_policies()
    with pytest.raises(ValueError, match="policy name must be a non-empty string"):
        register_policy(name)(lambda env: None)
    assert available_policies() == before
    env = fov_coverage_v0.parallel_env(n_agents=2)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        make_policy("nope", env)


@pytest.mark.parametrize("options", [5, "init", [1, 2], ("a", 3)])
def test_options_of_another_kind_are_refused(options):
    with pytest.raises(ValueError, match="options of policy 'bad_opts' must be"):
        register_policy("bad_opts", options=options)(lambda env: None)
    assert "bad_opts" not in available_policies()


def test_a_factory_that_is_not_callable_is_refused():
    with pytest.raises(ValueError, match="decorates a policy factory"):
        register_policy("not_callable")(5)
    assert "not_callable" not in available_policies()


def test_make_policy_with_a_name_of_another_type_is_a_value_error():
    env = fov_coverage_v0.parallel_env(n_agents=2)
    for name in (5, ["random"], None):
        with pytest.raises(ValueError, match="unknown policy"):
            make_policy(name, env)


def test_valid_registrations_still_work():
    from fov_marl.baselines.random_policy import RandomPolicy

    register_policy("mine", options=["x"])(lambda env, **kw: RandomPolicy(env))
    register_policy("mine_set", options={"y"})(lambda env, **kw: RandomPolicy(env))
    register_policy("mine_fn")(lambda env: RandomPolicy(env))
    assert {"mine", "mine_set", "mine_fn"} <= set(available_policies())
    env = fov_coverage_v0.parallel_env(n_agents=2)
    assert isinstance(make_policy("mine", env, x=1), RandomPolicy)
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['x'\] for policy 'mine_set'"):
        make_policy("mine_set", env, x=1)
