"""Scenario configuration: the paper's defaults and validation of every field."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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
    (
        "safety_distance_m",
        1.0,
        "(1.0, 1e6] (above 2 * robot_radius_m = 1.0; raise it or lower robot_radius_m)",
    ),
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
    (
        "init_min_separation_m",
        0.5,
        "[1.0, 1e6] (at least 2 * robot_radius_m = 1.0; raise it or lower robot_radius_m)",
    ),
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


def test_the_largest_team_is_accepted_where_it_fits():
    # 256 random starts 3 m apart do not fit in the default 40 m arena (Oler's bound: 211)
    assert make_config(n_agents=256, arena_size_m=100.0).n_agents == 256
    assert make_config(n_agents=211, init_min_separation_m=1.0).n_agents == 211


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


# ----------------------------------------------------------------------------- types
REAL_FIELDS = [
    f.name
    for f in dataclasses.fields(ScenarioConfig)
    if f.type in ("float", float) and f.name != "initial_poses"
]
WRONG_REALS = ["2.5", b"2.5", 2.5 + 0j, np.complex128(1.0), True, np.bool_(False), None, [2.5]]


def test_real_fields_are_all_listed():
    assert "fov_deg" in REAL_FIELDS and "crossing_radius_m" in REAL_FIELDS
    assert len(REAL_FIELDS) == 21


@pytest.mark.parametrize("name", REAL_FIELDS)
@pytest.mark.parametrize("scenario", ["coverage", "crossing"])
def test_wrongly_typed_reals_are_rejected_in_both_scenarios(name, scenario):
    """Issue 15: '2.5' was silently accepted or crashed at step(); now a ConfigError
    names the field (crossing fields included in coverage, and vice versa)."""
    for value in WRONG_REALS:
        with pytest.raises(ConfigError, match=f"^{name}") as err:
            make_config(scenario=scenario, **{name: value})
        assert "real number" in str(err.value), str(err.value)


@pytest.mark.parametrize(
    ("name", "value"),
    [("n_agents", 6.0), ("n_agents", "6"), ("n_agents", np.float64(6)), ("max_cycles", 10.0)],
)
def test_integers_must_be_integers(name, value):
    with pytest.raises(ConfigError, match=f"{name} must be an integer"):
        make_config(**{name: value})


def test_numpy_scalars_are_accepted_and_stored_as_python_numbers():
    c = make_config(
        n_agents=np.int32(4),
        fov_deg=np.float32(90.0),
        dt_s=np.array(0.1),
        max_cycles=np.uint16(50),
        meas_cov_diag=np.array([0.1, 0.1, 0.5], dtype=np.float32),
    )
    assert type(c.n_agents) is int and type(c.max_cycles) is int
    assert type(c.fov_deg) is float and c.fov_deg == 90.0 and type(c.dt_s) is float
    assert all(type(x) is float for x in c.meas_cov_diag)
    json.dumps(c.to_dict())  # nothing NumPy left


@pytest.mark.parametrize(
    "value",
    [["0.1", "0.1", "0.5"], "0.1,0.1,0.5", [0.1, 0.1, True], [0.1, 0.1, 1j], {0.1, 0.5}],
    ids=["strings", "str", "bool", "complex", "set"],
)
def test_sequences_must_hold_reals(value):
    with pytest.raises(ConfigError, match="meas_cov_diag"):
        make_config(meas_cov_diag=value)


@pytest.mark.parametrize(
    "poses",
    [
        [["5", "5", "0"], ["10", "5", "0"], ["20", "20", "0"]],
        np.ones((3, 3), dtype=bool),
        np.full((3, 3), 5.0, dtype=complex),
        np.full((3, 3), 5.0).astype(object),
        [[5.0, 5.0, 0.0], [10.0, 5.0], [20.0, 20.0, 0.0]],
        [[5.0, 5.0, None], [10.0, 5.0, 0.0], [20.0, 20.0, 0.0]],
        {"robot_0": [5.0, 5.0, 0.0]},
    ],
    ids=["strings", "bool", "complex", "object", "ragged", "none", "dict"],
)
def test_initial_poses_must_be_a_real_array(poses):
    with pytest.raises(ConfigError, match="initial_poses"):
        make_config(n_agents=3, initial_poses=poses)


def test_scenario_must_be_a_string_choice():
    for value in (None, 1, ["coverage"], b"coverage"):
        with pytest.raises(ConfigError, match="scenario must be one of"):
            ScenarioConfig(scenario=value)


# ----------------------------------------------------------------------------- cross fields
def test_crossing_fields_do_not_constrain_coverage():
    """Issue 15: arena_size_m=10 was rejected for coverage by crossing_radius_m = 12."""
    c = make_config(arena_size_m=10.0)
    assert c.crossing_radius_m == 12.0 and c.density_mean_m == (5.0, 5.0)
    make_config(crossing_radius_m=500.0, crossing_jitter_m=100.0)
    with pytest.raises(ConfigError, match=r"crossing_radius_m must be in \(0.0, 4.5\]") as err:
        make_config(scenario="crossing", arena_size_m=10.0)
    assert "arena_size_m = 10.0" in str(err.value)
    with pytest.raises(ConfigError, match=r"crossing_radius_m must be in \(0.0, 19.5\]"):
        make_config(scenario="crossing", crossing_radius_m=19.6)
    make_config(scenario="crossing", crossing_radius_m=19.5)
    with pytest.raises(ConfigError, match=r"crossing_jitter_m must be in \[0.0, 20.0\]"):
        make_config(scenario="crossing", crossing_jitter_m=21.0)


@pytest.mark.parametrize(
    ("changes", "fits"),
    [
        ({"n_agents": 31}, True),  # defaults R = 12 m, jitter 0.5 m: N <= 31
        ({"n_agents": 32}, False),
        ({"n_agents": 60}, False),  # red team 3: started in collision
        ({"crossing_radius_m": 1.0}, False),  # red team 3: N = 4 on a 1 m circle
        ({"crossing_radius_m": 1.0, "crossing_jitter_m": 0.0}, True),  # 1.414 m apart
        ({"crossing_radius_m": 0.7, "crossing_jitter_m": 0.0}, False),  # 0.99 m
        ({"crossing_jitter_m": 5.6}, True),
        ({"crossing_jitter_m": 5.7}, False),
        ({"n_agents": 2, "crossing_radius_m": 0.5, "crossing_jitter_m": 0.0}, True),
        ({"n_agents": 1, "crossing_radius_m": 1e-3}, True),  # one robot: nothing to hit
    ],
)
def test_crossing_ring_must_keep_every_jittered_start_apart(changes, fits):
    """Adjacent ring points are 2 R sin(π/N) apart and the jitter moves each by at most
    √2 j: a config whose worst draw puts two starts closer than 2 r is a ValueError
    naming crossing_radius_m, n_agents and crossing_jitter_m with the rule."""
    if fits:
        make_config(scenario="crossing", **changes)
        return
    with pytest.raises(ConfigError, match=r"^crossing_radius_m = .*n_agents = .*sin\(pi"):
        make_config(scenario="crossing", **changes)
    make_config(**changes)  # crossing fields never constrain coverage


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(2, 40),
    radius=st.floats(0.5, 19.5),
    jitter=st.floats(0.0, 3.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_every_accepted_crossing_layout_starts_without_collision(n, radius, jitter, seed):
    """Property: whatever the draw (edge jitter included), an accepted crossing config
    starts and targets its robots at least two radii apart."""
    from fov_marl.envs.world import crossing_layout

    try:
        cfg = make_config(
            scenario="crossing", n_agents=n, crossing_radius_m=radius, crossing_jitter_m=jitter
        )
    except ConfigError:
        return
    poses, targets = crossing_layout(cfg, np.random.default_rng(seed))
    for pts in (poses[:, :2], targets):
        d = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 2 * cfg.robot_radius_m - 1e-9


def test_coverage_fields_do_not_constrain_crossing():
    c = make_config(scenario="crossing", density_mean_m=(-5.0, 100.0), density_sigma_m=1e-3)
    assert c.density_mean_m == (-5.0, 100.0)
    with pytest.raises(ConfigError, match=r"density_mean_m\[x\] must be in \[0.0, 40.0\]"):
        make_config(density_mean_m=(-5.0, 20.0))
    with pytest.raises(ConfigError, match=r"density_sigma_m must be in .*at least eta_grid_m"):
        make_config(density_sigma_m=0.05)


def test_density_mean_follows_the_arena_only_when_not_given():
    assert make_config(arena_size_m=60.0).density_mean_m == (30.0, 30.0)
    assert make_config(arena_size_m=60.0, density_mean_m=(10, 10)).density_mean_m == (10.0, 10.0)
    off = make_config(density_mean_m=(10.0, 30.0))
    assert off.replace(arena_size_m=50.0).density_mean_m == (10.0, 30.0)
    assert ScenarioConfig().replace(arena_size_m=80.0).density_mean_m == (40.0, 40.0)


def test_random_starts_must_fit_in_the_arena():
    with pytest.raises(ConfigError, match="init_min_separation_m = 3.0: at most 4 robots fit"):
        make_config(arena_size_m=5.0)
    make_config(arena_size_m=5.0, n_agents=4)
    poses = [[1.0 + 1.1 * i, 1.0, 0.0] for i in range(3)]
    make_config(arena_size_m=5.0, n_agents=3, initial_poses=poses)  # given starts: no bound


# ----------------------------------------------------------------------------- resources
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"eta_grid_m": 1e-5}, r"eta_grid_m = 1e-05 .*4e\+06 cells per axis, more than .* 20000"),
        ({"eta_grid_m": 5e-324}, "eta_grid_m"),
        ({"sensing_radius_m": 1e5}, r"sensing_radius_m = 100000.0 .* limit of 500000"),
        ({"sensing_radius_m": 1e300}, r"sensing_radius_m must be in \(0.0, 1e6\]"),
        ({"n_agents": 256, "arena_size_m": 1000.0, "sensing_radius_m": 200.0}, "eta stencil"),
    ],
)
def test_resource_guards_name_the_field_and_the_limit(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        make_config(**kwargs)


def test_resource_guards_concern_coverage_only():
    make_config(scenario="crossing", eta_grid_m=1e-9, sensing_radius_m=1e6)


def test_negative_zero_is_normalised():
    c = make_config(scenario="crossing", crossing_jitter_m=-0.0)
    assert math.copysign(1.0, c.crossing_jitter_m) == 1.0


# ------------------------------------------------------------------ from_dict (issue 13)
def test_from_dict_inverts_to_dict_through_json():
    import json

    import numpy as np

    from fov_marl.config import ScenarioConfig, make_config

    poses = np.array([[5.0, 5.0, 0.1], [10.0, 12.0, -2.0]])
    for cfg in (
        make_config(),
        make_config(scenario="crossing", fov_deg=90.0, crossing_radius_m=10.0),
        make_config(n_agents=2, initial_poses=poses, arena_size_m=30.0),
    ):
        back = ScenarioConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
        assert back == cfg and back.to_dict() == cfg.to_dict()
        if cfg.initial_poses is not None:
            assert np.array_equal(back.initial_poses, cfg.initial_poses)


def test_from_dict_takes_subsets_and_rejects_unknown_or_bad_fields():
    import pytest

    from fov_marl.config import ConfigError, ScenarioConfig

    assert ScenarioConfig.from_dict({}).n_agents == 6
    assert ScenarioConfig.from_dict({"scenario": "crossing"}).n_agents == 4  # its defaults
    with pytest.raises(ConfigError, match=r"unknown config field\(s\) \['nosuch'\]"):
        ScenarioConfig.from_dict({"nosuch": 1, "fov_deg": 90})
    with pytest.raises(ValueError, match="fov_deg"):
        ScenarioConfig.from_dict({"fov_deg": 400})
    with pytest.raises(ConfigError, match="mapping"):
        ScenarioConfig.from_dict([("fov_deg", 90)])
    with pytest.raises(ConfigError, match="strings"):
        ScenarioConfig.from_dict({1: 2})
    with pytest.raises(ConfigError, match="scenario"):
        ScenarioConfig.from_dict({"scenario": "maze"})


def test_read_config_file_names_the_flag_and_the_file(tmp_path):
    import pytest

    from fov_marl.config import ConfigError, cli_overrides, read_config_file

    good = tmp_path / "c.json"
    good.write_text('{"scenario": "crossing", "fov_deg": 90}')
    assert read_config_file(good) == {"scenario": "crossing", "fov_deg": 90}
    for text, says in (("{nope", "not a readable JSON"), ("[1]", "JSON object"),
                       ('{"fov_deg": 0}', "fov_deg"), ('{"x": 1}', "unknown")):  # fmt: skip
        bad = tmp_path / "bad.json"
        bad.write_text(text)
        with pytest.raises(ConfigError, match=says) as exc:
            read_config_file(bad)
        assert str(exc.value).startswith(f"--config {bad}")
    with pytest.raises(ConfigError, match="not a readable"):
        read_config_file(tmp_path / "missing.json")
    scen, fields, sources = cli_overrides(good, ["fov_deg=60", "density_sigma_m=4"])
    assert scen == "crossing" and fields == {"fov_deg": 60, "density_sigma_m": 4}
    assert sources == {"fov_deg": "--env", "density_sigma_m": "--env"}
