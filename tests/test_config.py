"""Scenario configuration: the paper's defaults and validation of every field."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from fov_marl.config import ConfigError, ScenarioConfig, make_config


# ----------------------------------------------------------------------------- defaults
def test_defaults_are_the_papers_values():
    """design.md's table of Section VII parameters."""
    c = ScenarioConfig()
    assert c.scenario == "coverage"
    assert c.n_agents == 6
    assert c.arena_size_m == 40.0
    assert c.fov_deg == 120.0
    assert c.detection_range_m == 10.0
    assert c.sensing_radius_m == 6.0
    assert c.safety_distance_m == 2.0
    assert c.v_max_mps == 1.0
    assert c.meas_cov_diag == (0.1, 0.1, 0.5)
    # choices the paper leaves open, as documented in the module docstring
    assert c.density_mean_m == (20.0, 20.0)  # q_m at the arena centre
    assert c.density_sigma_m == 2.8
    assert c.dt_s == 0.2  # the authors' control period
    assert c.omega_max_radps == 1.5  # the authors' clip
    assert c.initial_poses is None
    assert c.collision_distance_m == 2 * c.robot_radius_m < c.safety_distance_m
    assert c.fov_rad == pytest.approx(math.radians(120.0))
    np.testing.assert_allclose(c.meas_std, np.sqrt([0.1, 0.1, 0.5]))
    assert not c.isotropic and ScenarioConfig(fov_deg=360.0).isotropic


def test_make_config_defaults_per_scenario():
    assert make_config() == ScenarioConfig()
    cross = make_config(scenario="crossing")
    assert cross.scenario == "crossing" and cross.n_agents == 4  # paper VII-D
    # everything else as in the coverage scenario
    assert dataclasses.replace(cross, scenario="coverage", n_agents=6) == ScenarioConfig()
    assert make_config(scenario="crossing", n_agents=6).n_agents == 6


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


# ----------------------------------------------------------------------------- ranges
# (field, bad value, text of the allowed range that the message must show)
BAD_VALUES = [
    ("scenario", "patrol", "('coverage', 'crossing')"),
    ("n_agents", 0, "[1, 256]"),
    ("n_agents", 257, "[1, 256]"),
    ("n_agents", 2.5, "[1, 256]"),
    ("n_agents", True, "[1, 256]"),
    ("max_cycles", 0, "[1, inf)"),
    ("arena_size_m", 4.0, "[5.0, 1000.0]"),
    ("arena_size_m", 2000.0, "[5.0, 1000.0]"),
    ("arena_size_m", math.nan, "[5.0, 1000.0]"),
    ("fov_deg", 0.0, "(0.0, 360.0]"),
    ("fov_deg", 360.5, "(0.0, 360.0]"),
    ("fov_deg", -30.0, "(0.0, 360.0]"),
    ("fov_deg", "wide", "(0.0, 360.0]"),
    ("detection_range_m", 0.0, "(0.0, 1e6]"),
    ("detection_range_m", math.inf, "(0.0, 1e6]"),
    ("sensing_radius_m", -1.0, "(0.0, 1e6]"),
    ("safety_distance_m", 0.0, "(0.0, 1e6]"),
    ("safety_distance_m", 1.0, "(1.0, 1e6] (above 2 * robot_radius_m = 1.0)"),
    ("robot_radius_m", 0.0, "(0.0, 1e6]"),
    ("robot_radius_m", 10.0, "(0.0, 10.0) (below arena_size_m / 4 = 10.0)"),
    ("v_max_mps", 0.0, "(0.0, 1e6]"),
    ("omega_max_radps", -1.5, "(0.0, 1e6]"),
    ("meas_cov_diag", (-0.1, 0.1, 0.5), "meas_cov_diag[x] must be in [0.0, 1e6]"),
    ("meas_cov_diag", (0.1, 0.1, math.nan), "meas_cov_diag[theta] must be finite"),
    ("meas_cov_diag", (0.1, 0.1), "sequence of 3 real numbers"),
    ("meas_noise_clip_sigma", 0.5, "[1.0, 1000.0]"),
    ("density_mean_m", (-1.0, 20.0), "density_mean_m[x] must be in [0.0, 40.0]"),
    ("density_mean_m", (20.0, 40.5), "density_mean_m[y] must be in [0.0, 40.0]"),
    ("density_mean_m", (20.0, 20.0, 1.0), "sequence of 2 real numbers"),
    ("density_sigma_m", 0.0, "(0.0, 1e6]"),
    ("dt_s", 0.0, "(0.0, 5.0]"),
    ("dt_s", 6.0, "(0.0, 5.0]"),
    ("init_min_separation_m", 0.5, "[1.0, 1e6] (at least 2 * robot_radius_m = 1.0)"),
    ("crossing_radius_m", 0.0, "(0.0, 1e6]"),
    ("crossing_radius_m", -1.0, "(0.0, 1e6]"),
    ("crossing_jitter_m", -0.1, "[0.0, 1e6]"),
    ("target_tolerance_m", 0.0, "(0.0, 1e6]"),
    ("eta_grid_m", 0.0, "(0.0, 1.0]"),
    ("eta_grid_m", 1.5, "(0.0, 1.0]"),
    ("reward_eta_gain", -1.0, "[0.0, 1e9]"),
    ("progress_gain", -1.0, "[0.0, 1e9]"),
    ("arrival_bonus", -1.0, "[0.0, 1e9]"),
    ("collision_penalty", -1.0, "[0.0, 1e9]"),
    ("safety_penalty", -1.0, "[0.0, 1e9]"),
]


@pytest.mark.parametrize(
    ("name", "value", "allowed"), BAD_VALUES, ids=[f"{n}={v!r}" for n, v, _ in BAD_VALUES]
)
def test_out_of_range_field_raises_naming_field_and_range(name, value, allowed):
    for build in (lambda: ScenarioConfig(**{name: value}), lambda: make_config(**{name: value})):
        with pytest.raises(ValueError) as err:
            build()
        assert isinstance(err.value, ConfigError)
        assert name in str(err.value)
        assert allowed in str(err.value), str(err.value)


def test_every_field_has_a_range_test():
    """A new field must come with its validation case in BAD_VALUES (initial_poses has
    its own tests below)."""
    fields = {f.name for f in dataclasses.fields(ScenarioConfig)} - {"initial_poses"}
    assert fields == {name for name, _, _ in BAD_VALUES}


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("n_agents", 1),
        ("n_agents", 256),
        ("n_agents", np.int64(12)),
        ("fov_deg", 360.0),
        ("fov_deg", 1e-3),
        ("meas_cov_diag", (0.0, 0.0, 0.0)),
        ("density_mean_m", (0.0, 40.0)),
        ("dt_s", 5.0),
        ("eta_grid_m", 1.0),
        ("safety_distance_m", 1.0 + 1e-9),
    ],
)
def test_boundary_values_are_accepted(name, value):
    c = make_config(**{name: value})
    assert np.all(np.asarray(getattr(c, name)) == np.asarray(value))


def test_sequences_are_stored_as_float_tuples():
    c = make_config(meas_cov_diag=np.array([1, 2, 3]), density_mean_m=[10, 30])
    assert c.meas_cov_diag == (1.0, 2.0, 3.0) and c.density_mean_m == (10.0, 30.0)
    assert all(type(x) is float for x in c.meas_cov_diag + c.density_mean_m)


# ----------------------------------------------------------------------------- keywords
def test_unknown_keyword_is_named():
    with pytest.raises(ConfigError, match="'fov'") as err:
        make_config(fov=90.0)
    assert "fov_deg" in str(err.value)  # the valid names are listed
    with pytest.raises(ConfigError, match="'n_robots'"):
        make_config(n_agents=3, n_robots=3)


def test_replace_validates_and_copies():
    base = ScenarioConfig()
    c = base.replace(fov_deg=360.0, n_agents=9)
    assert (c.fov_deg, c.n_agents) == (360.0, 9)
    assert base.fov_deg == 120.0 and base.n_agents == 6
    with pytest.raises(ConfigError, match="fov_deg"):
        base.replace(fov_deg=400.0)
    with pytest.raises(ConfigError, match="'bogus'"):
        base.replace(bogus=1)
    assert base.replace() == base


def test_frozen():
    c = ScenarioConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.n_agents = 3  # type: ignore[misc]
    poses = make_config(n_agents=2, initial_poses=[[5, 5, 0], [10, 10, 0]]).initial_poses
    with pytest.raises(ValueError, match="read-only"):
        poses[0, 0] = 1.0


def test_to_dict_is_json_and_round_trips():
    c = make_config(scenario="crossing", fov_deg=60.0)
    d = json.loads(json.dumps(c.to_dict()))
    assert make_config(**d) == c
    with_poses = make_config(n_agents=2, initial_poses=[[5, 5, 0], [10, 10, 1]])
    d = json.loads(json.dumps(with_poses.to_dict()))
    np.testing.assert_array_equal(make_config(**d).initial_poses, with_poses.initial_poses)


# ----------------------------------------------------------------------------- initial poses
GOOD_POSES = [[5.0, 5.0, 0.0], [10.0, 5.0, 1.0], [20.0, 30.0, -2.0]]


def test_initial_poses_accepted_copied_wrapped():
    src = np.array(GOOD_POSES)
    src[2, 2] = 7.0  # yaw outside [-π, π)
    c = make_config(n_agents=3, initial_poses=src)
    assert c.initial_poses.shape == (3, 3) and c.initial_poses.dtype == np.float64
    np.testing.assert_array_equal(c.initial_poses[:, :2], src[:, :2])
    assert c.initial_poses[2, 2] == pytest.approx(7.0 - 2 * np.pi)
    src[0, 0] = 30.0  # the config holds its own copy
    assert c.initial_poses[0, 0] == 5.0


@pytest.mark.parametrize(
    ("poses", "match"),
    [
        (np.zeros((2, 3)) + 5.0, r"shape \(n_agents, 3\) = \(3, 3\)"),  # too few robots
        (np.zeros((3, 2)) + 5.0, r"shape \(n_agents, 3\) = \(3, 3\)"),  # no yaw
        ("not poses", "initial_poses"),
        ([[5.0, 5.0, 0.0], [10.0, np.nan, 0.0], [20.0, 20.0, 0.0]], "finite"),
        ([[5.0, 5.0, 0.0], [10.0, 5.0, np.inf], [20.0, 20.0, 0.0]], "finite"),
        ([[5.0, 5.0, 0.0], [10.0, 5.0, 0.0], [41.0, 20.0, 0.0]], r"initial_poses\[2\]"),
        ([[5.0, 5.0, 0.0], [10.0, 5.0, 0.0], [20.0, 0.2, 0.0]], r"\[0.5, 39.5\]"),
        ([[5.0, 5.0, 0.0], [5.5, 5.3, 0.0], [20.0, 20.0, 0.0]], "robots 0 and 1"),
        ([[5.0, 5.0, 0.0], [20.0, 20.0, 0.0], [20.9, 20.0, 0.0]], "robots 1 and 2"),
    ],
    ids=["rows", "cols", "type", "nan", "inf", "outside", "on-wall", "close01", "close12"],
)
def test_initial_poses_rejected(poses, match):
    with pytest.raises(ConfigError, match="initial_poses") as err:
        make_config(n_agents=3, initial_poses=poses)
    assert err.match(match)


def test_robots_exactly_two_radii_apart_are_accepted():
    c = make_config(n_agents=2, initial_poses=[[5.0, 5.0, 0.0], [6.0, 5.0, 0.0]])
    assert c.initial_poses.shape == (2, 2 + 1)


def test_changing_n_agents_drops_stale_initial_poses():
    c = make_config(n_agents=3, initial_poses=GOOD_POSES)
    assert c.replace(n_agents=4).initial_poses is None
    assert c.replace(fov_deg=60.0).initial_poses is not None
    with pytest.raises(ConfigError, match="initial_poses"):
        c.replace(n_agents=4, initial_poses=GOOD_POSES)
