"""Observation layout and the action <-> body-velocity mapping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fov_marl.spaces import (
    CUE_SIZE,
    SLOT_SIZE,
    ObservationLayout,
    action_to_velocity,
    velocity_to_action,
)

V_MAX, W_MAX = 1.0, 1.5


# ----------------------------------------------------------------------------- layout
@pytest.mark.parametrize(("n", "size"), [(1, 7), (2, 12), (4, 22), (6, 32), (12, 62)])
def test_sizes(n, size):
    for i in range(n):
        lay = ObservationLayout(n, i)
        assert lay.n_slots == n - 1
        assert lay.size == size == SLOT_SIZE * (n - 1) + CUE_SIZE
        assert lay.cue_slice == slice(size - CUE_SIZE, size)


@pytest.mark.parametrize("n", [1, 2, 6, 12])
def test_slot_ids_skip_self_in_ascending_order(n):
    for i in range(n):
        ids = ObservationLayout(n, i).neighbour_ids
        assert ids.tolist() == [j for j in range(n) if j != i]
        for k, j in enumerate(ids):
            assert j == (k if k < i else k + 1)  # the module docstring's rule


def test_layout_rejects_bad_indices():
    with pytest.raises(ValueError, match="agent_index"):
        ObservationLayout(3, 3)
    with pytest.raises(ValueError, match="agent_index"):
        ObservationLayout(3, -1)
    with pytest.raises(ValueError, match="n_agents"):
        ObservationLayout(0, 0)
    with pytest.raises(ValueError, match="n_agents"):
        ObservationLayout(2.0, 0)  # type: ignore[arg-type]


def encode(lay: ObservationLayout, seen: dict[int, tuple[float, float, float]], cue) -> np.ndarray:
    """Write an observation by hand, following the module docstring's table."""
    obs = np.zeros(lay.size, dtype=np.float32)
    for k, j in enumerate(lay.neighbour_ids):
        if j in seen:
            x, y, th = seen[j]
            obs[SLOT_SIZE * k : SLOT_SIZE * (k + 1)] = [1.0, x, y, math.cos(th), math.sin(th)]
    obs[lay.cue_slice] = cue
    return obs


def test_slots_cue_and_decode():
    lay = ObservationLayout(5, 2)  # slots hold robots 0, 1, 3, 4
    seen = {0: (3.0, -1.0, 0.5), 4: (7.5, 2.25, -2.0)}
    cue = [12.0, 30.0, math.cos(-2.5), math.sin(-2.5), 4.0, -3.0, 2.8]
    obs = encode(lay, seen, cue)
    assert lay.slots(obs).shape == (4, SLOT_SIZE)
    assert lay.slots(obs)[:, 0].tolist() == [1.0, 0.0, 0.0, 1.0]
    np.testing.assert_allclose(lay.cue(obs), cue, rtol=1e-6)
    det = lay.decode(obs)
    assert det.ids.tolist() == [0, 4]
    np.testing.assert_allclose(det.p_body, [[3.0, -1.0], [7.5, 2.25]], rtol=1e-6)
    np.testing.assert_allclose(det.yaw_rel_rad, [0.5, -2.0], atol=1e-6)
    assert det.p_body.dtype == np.float64
    np.testing.assert_allclose(lay.own_pose_world(obs), [12.0, 30.0, -2.5], atol=1e-6)
    np.testing.assert_allclose(lay.goal_body(obs), [4.0, -3.0])


def test_decode_nothing_seen_and_single_robot():
    lay = ObservationLayout(4, 0)
    det = lay.decode(np.zeros(lay.size, dtype=np.float32))
    assert det.ids.shape == (0,) and det.p_body.shape == (0, 2) and det.yaw_rel_rad.shape == (0,)
    alone = ObservationLayout(1, 0)
    obs = encode(alone, {}, [1.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0])
    assert alone.decode(obs).ids.shape == (0,)
    np.testing.assert_allclose(alone.own_pose_world(obs), [1.0, 2.0, 0.0])


def test_decode_rejects_wrong_shape_naming_the_robot():
    lay = ObservationLayout(3, 1)
    with pytest.raises(ValueError, match=r"robot_1.*\(17,\)"):
        lay.decode(np.zeros(16))
    with pytest.raises(ValueError, match="robot_1"):
        lay.decode(np.zeros((1, 17)))


@given(
    st.integers(2, 12).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.integers(0, n - 1),
            st.lists(st.booleans(), min_size=n - 1, max_size=n - 1),
        )
    ),
    st.floats(-10, 10),
    st.floats(-10, 10),
    st.floats(-math.pi, math.pi),
)
def test_decode_round_trip_property(layout_case, x, y, th):
    n, i, flags = layout_case
    lay = ObservationLayout(n, i)
    seen = {int(j): (x, y, th) for j, f in zip(lay.neighbour_ids, flags, strict=True) if f}
    det = lay.decode(encode(lay, seen, np.zeros(CUE_SIZE)))
    assert det.ids.tolist() == sorted(seen)
    np.testing.assert_allclose(det.p_body, np.tile([x, y], (len(seen), 1)), atol=1e-5)
    dth = np.angle(np.exp(1j * (det.yaw_rel_rad - th)))
    np.testing.assert_allclose(dth, 0.0, atol=1e-6)


@given(
    st.integers(1, 8),
    st.integers(1, 4),
    st.integers(0, 2**32 - 1),
)
def test_batched_slots_and_cue_equal_the_per_row_decode(n, rows, seed):
    """The (..., size) forms the tracker and the pipeline read every robot with are, row
    by row, :meth:`decode`, :meth:`own_pose_world` and :meth:`goal_body`, bit for bit."""
    rng = np.random.default_rng(seed)
    lay = ObservationLayout(n, 0)
    obs = rng.normal(size=(2, rows, lay.size)).astype(np.float32)
    obs[..., : SLOT_SIZE * (n - 1) : SLOT_SIZE] = rng.integers(0, 2, (2, rows, n - 1))
    det, p_body, yaw = lay.slot_arrays(obs)
    pose = lay.own_pose_world(obs)
    goal = lay.goal_body(obs)
    assert det.shape == (2, rows, n - 1) and p_body.shape == (2, rows, n - 1, 2)
    assert pose.shape == (2, rows, 3) and goal.shape == (2, rows, 2)
    for b in range(2):
        for r in range(rows):
            one = lay.decode(obs[b, r])
            assert lay.neighbour_ids[det[b, r]].tolist() == one.ids.tolist()
            assert np.array_equal(p_body[b, r][det[b, r]], one.p_body)
            assert np.array_equal(yaw[b, r][det[b, r]], one.yaw_rel_rad)
            assert np.array_equal(pose[b, r], lay.own_pose_world(obs[b, r]))
            assert np.array_equal(goal[b, r], lay.goal_body(obs[b, r]))
            assert np.array_equal(pose[b, r, :2], obs[b, r, lay.cue_slice][:2].astype(np.float64))


# ----------------------------------------------------------------------------- actions
def test_action_to_velocity_known_values():
    v, w = action_to_velocity(np.array([0.5, -0.25, 1.0]), V_MAX, W_MAX)
    np.testing.assert_allclose(v, [0.5, -0.25])
    assert w == pytest.approx(1.5)
    # out of the box: clipped per component, then the planar part shrunk to v_max
    v, w = action_to_velocity(np.array([3.0, 0.0, -7.0]), 2.0, W_MAX)
    np.testing.assert_allclose(v, [2.0, 0.0])
    assert w == pytest.approx(-1.5)
    v, _ = action_to_velocity(np.array([1.0, 1.0, 0.0]), 2.0, W_MAX)  # diagonal
    np.testing.assert_allclose(v, [math.sqrt(2.0), math.sqrt(2.0)])
    v, w = action_to_velocity(np.zeros(3), V_MAX, W_MAX)
    np.testing.assert_array_equal(v, [0.0, 0.0])
    assert w == 0.0


def test_action_to_velocity_batch():
    a = np.random.default_rng(0).uniform(-2, 2, (4, 5, 3)).astype(np.float32)
    v, w = action_to_velocity(a, V_MAX, W_MAX)
    assert v.shape == (4, 5, 2) and w.shape == (4, 5)
    v1, w1 = action_to_velocity(a[3, 2], V_MAX, W_MAX)
    np.testing.assert_allclose(v[3, 2], v1)
    assert w[3, 2] == pytest.approx(float(w1))


finite = st.floats(-1e6, 1e6, allow_nan=False)


@given(st.tuples(finite, finite, finite), st.floats(0.1, 5.0), st.floats(0.1, 5.0))
def test_action_to_velocity_respects_limits(a, v_max, w_max):
    a = np.array(a)
    v, w = action_to_velocity(a, v_max, w_max)
    assert np.linalg.norm(v) <= v_max * (1 + 1e-12)
    assert abs(w) <= w_max
    clipped = np.clip(a, -1, 1)
    if np.linalg.norm(clipped[:2]) <= 1.0:  # inside the unit disk: plain scaling
        np.testing.assert_allclose(v, clipped[:2] * v_max, rtol=1e-12, atol=1e-300)
    elif np.linalg.norm(clipped[:2]) > 0:  # shrunk along the commanded direction
        assert np.linalg.norm(v) == pytest.approx(v_max)
        d = clipped[:2] / np.linalg.norm(clipped[:2])
        np.testing.assert_allclose(v / np.linalg.norm(v), d, atol=1e-12)
    assert w == pytest.approx(clipped[2] * w_max)


@given(
    st.floats(0.0, 1.0),
    st.floats(-math.pi, math.pi),
    st.floats(-1.0, 1.0),
    st.floats(0.1, 5.0),
    st.floats(0.1, 5.0),
)
def test_velocity_action_round_trip(speed_frac, heading, w_frac, v_max, w_max):
    v = speed_frac * v_max * np.array([math.cos(heading), math.sin(heading)])
    w = w_frac * w_max
    a = velocity_to_action(v, w, v_max, w_max)
    assert a.dtype == np.float32 and a.shape == (3,)
    assert np.all(np.abs(a) <= 1.0)
    v2, w2 = action_to_velocity(a, v_max, w_max)
    # float32 actions: relative precision 6e-8 of the limits
    np.testing.assert_allclose(v2, v, atol=2e-7 * v_max)
    assert w2 == pytest.approx(w, abs=2e-7 * w_max)


def test_velocity_to_action_batch_and_clip():
    v = np.array([[0.3, 0.4], [1.0, 0.0], [0.0, -1.0 - 1e-12]])
    w = np.array([0.0, -1.5, 1.5 + 1e-12])
    a = velocity_to_action(v, w, V_MAX, W_MAX)
    assert a.shape == (3, 3)
    np.testing.assert_allclose(a, [[0.3, 0.4, 0.0], [1.0, 0.0, -1.0], [0.0, -1.0, 1.0]])
