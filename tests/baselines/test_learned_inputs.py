"""Red team 8 (F05, F06, F21): a learned-policy folder or env the policy cannot use is a
``ValueError`` at load time naming the file and the field, never NaN actions, a
``KeyError``, a ``zipfile`` error or a silent misreading of the observation."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fov_marl.baselines import make_policy
from fov_marl.baselines.learned import SetActorWeights, shipped_model_dir
from fov_marl.envs import fov_coverage_v0
from fov_marl.wrappers import BeliefObservationWrapper

SHIP = shipped_model_dir()


def _config() -> dict[str, Any]:
    return json.loads((SHIP / "config.json").read_text(encoding="utf-8"))


def _weights() -> dict[str, np.ndarray]:
    with np.load(SHIP / "weights.npz") as z:
        return {k: z[k] for k in z.files}


def _folder(tmp_path: Path, config: dict[str, Any], weights: dict[str, np.ndarray]) -> Path:
    d = tmp_path / "model"
    d.mkdir()
    (d / "config.json").write_text(json.dumps(config), encoding="utf-8")
    np.savez(d / "weights.npz", **weights)
    return d


@pytest.fixture
def env():
    return fov_coverage_v0.parallel_env(n_agents=2)


@pytest.mark.parametrize(
    "cut",
    [
        lambda b: b[: len(b) // 2],  # truncated
        lambda b: b[:-100],  # the end cut off
        lambda b: b[:2000] + bytes(500) + b[2500:],  # corrupted: Bad CRC-32
    ],
    ids=["half", "tail", "crc"],
)
def test_a_truncated_or_corrupted_weights_file_is_a_value_error_naming_it(tmp_path, env, cut):
    """F05: zipfile.BadZipFile ("File is not a zip file", "Bad CRC-32") leaked."""
    d = tmp_path / "model"
    d.mkdir()
    shutil.copy(SHIP / "config.json", d / "config.json")
    (d / "weights.npz").write_bytes(cut((SHIP / "weights.npz").read_bytes()))
    with pytest.raises(ValueError, match=r"weights\.npz: not a readable \.npz file"):
        make_policy("learned", env, path=str(d))


def test_a_bare_npy_array_is_not_a_weights_archive(tmp_path):
    d = tmp_path / "model"
    d.mkdir()
    shutil.copy(SHIP / "config.json", d / "config.json")
    with open(d / "weights.npz", "wb") as f:
        np.save(f, np.zeros(3))
    with pytest.raises(ValueError, match=r"weights\.npz: not a readable \.npz file"):
        SetActorWeights.load(d)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_weights_are_refused_at_load_time(tmp_path, env, bad):
    """F06: NaN in phi.0.weight loaded, then every robot's action was NaN."""
    w = _weights()
    w["phi.0.weight"] = w["phi.0.weight"].copy()
    w["phi.0.weight"][3, 1] = bad
    d = _folder(tmp_path, _config(), w)
    with pytest.raises(ValueError, match=r"weights\.npz: phi\.0\.weight must be finite"):
        make_policy("learned", env, path=str(d))


def test_non_numeric_weights_are_refused(tmp_path):
    w = _weights()
    w["action.bias"] = np.array(["a", "b", "c"])
    d = _folder(tmp_path, _config(), w)
    with pytest.raises(ValueError, match=r"weights\.npz: action\.bias must be a numeric array"):
        SetActorWeights.load(d)


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("neighbour_m", 0, r"feature_scales\.neighbour_m must be in \(0\.0, inf\)"),
        ("neighbour_m", -10.0, r"feature_scales\.neighbour_m must be in"),
        ("arena_half_m", "20", r"feature_scales\.arena_half_m must be a real number"),
        ("count", 0.0, r"feature_scales\.count must be in"),
        ("arena_centre_m", [20.0], r"feature_scales\.arena_centre_m must be a sequence of 2"),
        ("arena_centre_m", [20.0, None], r"feature_scales\.arena_centre_m\[1\]"),
    ],
)
def test_bad_feature_scales_name_the_file_and_field(tmp_path, env, key, value, match):
    """F06: feature_scales.neighbour_m = 0 loaded and made every action NaN."""
    cfg = _config()
    cfg["feature_scales"][key] = value
    d = _folder(tmp_path, cfg, _weights())
    with pytest.raises(ValueError, match=r"config\.json: " + match):
        make_policy("learned", env, path=str(d))


@pytest.mark.parametrize("key", ["neighbour_m", "arena_half_m", "arena_centre_m"])
def test_a_missing_feature_scale_is_named(tmp_path, env, key):
    """F06: a config.json without neighbour_m raised KeyError."""
    cfg = _config()
    del cfg["feature_scales"][key]
    d = _folder(tmp_path, cfg, _weights())
    with pytest.raises(ValueError, match=rf"config\.json: feature_scales\.{key} is missing"):
        make_policy("learned", env, path=str(d))


def test_bad_arch_entries_are_named(tmp_path):
    cfg = _config()
    cfg["arch"]["bounded_mean"] = "yes"
    d = _folder(tmp_path, cfg, _weights())
    with pytest.raises(ValueError, match=r"config\.json: arch\.bounded_mean must be a bool"):
        SetActorWeights.load(d)


def test_a_valid_copy_of_the_shipped_model_acts_as_the_shipped_one(tmp_path, env):
    d = _folder(tmp_path, _config(), _weights())
    obs, _ = env.reset(seed=0)
    a = make_policy("learned", env, path=str(d)).act(obs)
    b = make_policy("learned", env).act(obs)
    for k in obs:
        assert np.isfinite(a[k]).all() and np.array_equal(a[k], b[k])


def test_a_path_of_the_wrong_type_is_a_value_error(env):
    with pytest.raises(ValueError, match="path must be a model folder"):
        make_policy("learned", env, path=5)


@pytest.mark.parametrize("n_agents", [4, 6])
def test_a_belief_wrapped_env_is_refused(n_agents):
    """F21: at N = 6 the 72 entries (= 5 * 13 + 7) were read as 13 neighbour slots."""
    env = BeliefObservationWrapper(fov_coverage_v0.parallel_env(n_agents=n_agents))
    want = 5 * (n_agents - 1) + 7
    with pytest.raises(ValueError, match=rf"{want} entries for n_agents = {n_agents}"):
        make_policy("learned", env)


def test_the_safety_filter_keeps_the_layout_and_is_accepted():
    from fov_marl.wrappers import SafetyFilterWrapper

    env = SafetyFilterWrapper(fov_coverage_v0.parallel_env(n_agents=2))
    obs, _ = env.reset(seed=0)
    assert set(make_policy("learned", env).act(obs)) == set(obs)
