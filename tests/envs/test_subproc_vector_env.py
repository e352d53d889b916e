"""SubprocVectorEnv: B copies over W worker processes give the one-process numbers."""

from __future__ import annotations

import functools
import os
import signal

import numpy as np
import pytest

from fov_marl.config import make_config
from fov_marl.envs import SubprocVectorEnv, build_raw_vector_env, fov_coverage_v0, fov_crossing_v0
from fov_marl.envs.subproc import merge_vector_infos
from fov_marl.validation import ConfigError
from fov_marl.wrappers import build_filtered_vector_env

N = 4


def _assert_same_step(a, b) -> None:
    """Two ``step`` (or ``reset``) returns are bit-identical, infos entry by entry."""
    assert len(a) == len(b)
    for x, y in zip(a[:-1], b[:-1], strict=True):
        np.testing.assert_array_equal(x, y)
        assert np.asarray(x).dtype == np.asarray(y).dtype
    _assert_same_infos(a[-1], b[-1])


def _assert_same_infos(x, y) -> None:
    assert set(x) == set(y)
    for k in x:
        if isinstance(x[k], dict):
            _assert_same_infos(x[k], y[k])
        else:
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)
            assert np.asarray(x[k]).shape == np.asarray(y[k]).shape


def _run_both(make, B: int, workers: int, steps: int, seed: int = 5) -> int:
    """Step ``make(B)`` and its W-shard SubprocVectorEnv with the same random actions;
    return how many copy-episodes ended (the auto-resets the comparison crossed)."""
    one = make(B)
    rng = np.random.default_rng(seed)
    done = 0
    with SubprocVectorEnv(make, B, workers) as sub:
        _assert_same_step(one.reset(seed=seed), sub.reset(seed=seed))
        for _ in range(steps):
            act = rng.uniform(-1.2, 1.2, (B, one.n_agents, 3))
            a, b = one.step(act), sub.step(act)
            _assert_same_step(a, b)
            done += int(a[4]["_final_obs"].sum())
        np.testing.assert_array_equal(one.poses, sub.poses)
        np.testing.assert_array_equal(one.num_steps, sub.num_steps)
        np.testing.assert_array_equal(one.state(), sub.state())
        if one.targets is None:
            assert sub.targets is None
        else:
            np.testing.assert_array_equal(one.targets, sub.targets)
        # an unseeded reset continues every copy's generator, in both
        _assert_same_step(one.reset(), sub.reset())
    return done


@pytest.mark.parametrize(
    ("scenario", "B", "workers", "eta"),
    [
        ("coverage", 5, 2, "exact"),
        ("crossing", 4, 3, "exact"),
        ("coverage", 3, 3, "exact"),
        ("coverage", 6, 2, "strip"),  # the strip η of a copy did depend on its batch
    ],
)
def test_raw_shards_are_bit_identical_to_one_process_across_auto_resets(scenario, B, workers, eta):
    cfg = make_config(scenario=scenario, n_agents=N)
    make = functools.partial(build_raw_vector_env, config=cfg, max_cycles=7, eta_method=eta)
    assert _run_both(make, B, workers, steps=16) >= 2 * B  # every copy reset at least twice


def test_filtered_shards_are_bit_identical_to_one_filter_over_all_copies():
    """Behind the filter (tracker bank and batched controller per shard): the applied
    actions, statuses and interventions equal one VectorSafetyFilterWrapper over all B
    copies bit for bit, also after the trackers of finished copies restart; a seed
    sequence reaches the filters as in one process. The crowded arena is where the
    batched controller's padding used to round a copy's actions by its batch's
    composition (red team: N = 8, 12 m)."""
    cfg = make_config(n_agents=8, arena_size_m=12.0, density_mean_m=(6.0, 6.0))
    make = functools.partial(
        build_filtered_vector_env,
        config=cfg,
        max_cycles=15,
        tracker_params={"n_particles_total": 300},
    )
    one = make(3)
    rng = np.random.default_rng(1)
    changed = done = 0
    with SubprocVectorEnv(make, 3, 2) as sub:
        for seed in (2, [5, None, 9]):
            _assert_same_step(one.reset(seed=seed), sub.reset(seed=seed))
            for _ in range(32):
                act = rng.uniform(-1, 1, (3, 8, 3))
                a, b = one.step(act), sub.step(act)
                _assert_same_step(a, b)
                changed += int(a[4]["safety"]["intervened"].sum())
                done += int(a[4]["_final_obs"].sum())
        assert sub.last_cpu_s is not None and sub.last_cpu_s > 0
        # max_cycles set on the filtered shards reaches their envs
        sub.max_cycles = 2
        assert sub.get_attr("max_cycles") == [2, 2]
        sub.reset(seed=0)
        sub.step(np.zeros((3, 8, 3)))
        *_, infos = sub.step(np.zeros((3, 8, 3)))
        assert infos["_final_obs"].all()
    assert changed > 0 and done >= 12


def test_vector_env_workers_keyword_and_seed_sequences():
    """``vector_env(..., workers=W)`` of both scenarios; a sequence of B seeds is sliced
    over the shards; ``max_cycles`` set on the parent reaches every shard."""
    for mod in (fov_coverage_v0, fov_crossing_v0):
        one = mod.vector_env(num_envs=3, n_agents=N)
        sub = mod.vector_env(num_envs=3, n_agents=N, workers=2)
        try:
            assert isinstance(sub, SubprocVectorEnv) and sub.workers == 2
            assert sub.config == one.config and sub.possible_agents == one.possible_agents
            assert sub.observation_space == one.observation_space
            assert sub.action_space == one.action_space
            assert sub.single_observation_space == one.single_observation_space
            _assert_same_step(one.reset(seed=[7, 9, 3]), sub.reset(seed=[7, 9, 3]))
            # None continues that copy's generator, in its shard as in one process
            _assert_same_step(one.reset(seed=[7, None, 3]), sub.reset(seed=[7, None, 3]))
            # a bad value is refused in the parent: no shard takes it
            for bad in ("x", 2.7, 0):
                with pytest.raises(ValueError, match="max_cycles must be an integer"):
                    sub.max_cycles = bad
            assert sub.get_attr("max_cycles") == [1000, 1000] and sub.max_cycles == 1000
            sub.max_cycles = 2
            one.max_cycles = 2
            assert sub.get_attr("max_cycles") == [2, 2]
            zero = np.zeros((3, N, 3))
            sub.step(zero)
            *_, infos = sub.step(zero)
            assert infos["_final_obs"].all() and "reset_metrics" in infos
        finally:
            sub.close()
    assert isinstance(fov_coverage_v0.vector_env(num_envs=2, workers=1), type(one))


def test_merge_fills_reset_metrics_of_shards_without_a_finished_copy():
    a = {"metrics": {"eta": np.array([0.1])}, "_final_obs": np.array([False])}
    b = {
        "metrics": {"eta": np.array([0.2, 0.3])},
        "_final_obs": np.array([True, False]),
        "reset_metrics": {"eta": np.array([0.0, 0.3])},
    }
    m = merge_vector_infos([a, b])
    np.testing.assert_array_equal(m["reset_metrics"]["eta"], [0.1, 0.0, 0.3])
    np.testing.assert_array_equal(m["metrics"]["eta"], [0.1, 0.2, 0.3])
    with pytest.raises(RuntimeError, match="safety"):
        merge_vector_infos([a, {**b, "safety": {"x": np.zeros(2)}}])


def _raise_value_error(n: int):
    raise ValueError(f"bad shard of {n} copies")


def _raise_key_error(n: int):
    raise KeyError("boom")


def _wrong_size(n: int):
    return build_raw_vector_env(n + 1, config=make_config(n_agents=N))


def test_copies_pickles_and_interrupted_calls_leave_the_env_working():
    """Copying or pickling raises (a copy would close the original's pipes when
    collected); an answer left unread (a Ctrl-C while waiting) is not read by the next
    call."""
    import copy
    import pickle

    make = functools.partial(build_raw_vector_env, config=make_config(n_agents=N))
    one = make(3)
    with SubprocVectorEnv(make, 3, 2) as sub:
        for fn in (copy.copy, copy.deepcopy, pickle.dumps):
            with pytest.raises(TypeError, match="SubprocVectorEnv cannot be"):
                fn(sub)
        _assert_same_step(one.reset(seed=1), sub.reset(seed=1))
        act = np.zeros((3, N, 3))
        sub._seq += 1  # what a step interrupted before its answers leaves
        for w in range(sub.workers):
            blob = pickle.dumps(("step", act[sub._starts[w] : sub._starts[w + 1]]))
            sub._conns[w].send((sub._seq, blob))
            sub._sent[w] = sub._seq
        one.step(act)
        np.testing.assert_array_equal(sub.num_steps, one.num_steps)  # not the stale step
        np.testing.assert_array_equal(sub.poses, one.poses)
        _assert_same_step(one.step(act), sub.step(act))


_INTERRUPTED = """
import signal, sys, time
import numpy as np
from fov_marl.envs import fov_coverage_v0

class Deadline(Exception):
    pass


RAISED = {"ctrl-c": KeyboardInterrupt, "timeout": TimeoutError, "custom": Deadline}[sys.argv[2]]


def interrupt(*_):
    raise RAISED("deadline")

if __name__ == "__main__":
    sub = fov_coverage_v0.vector_env(num_envs=8, n_agents=4, workers=2, max_cycles=10**6)
    one = fov_coverage_v0.vector_env(num_envs=8, n_agents=4, max_cycles=10**6)
    sub.reset(seed=0)
    a = np.zeros((8, 4, 3))
    rng = np.random.default_rng(int(sys.argv[1]))
    signal.signal(signal.SIGALRM, interrupt)
    hits, t_end = 0, time.time() + 4.0
    while time.time() < t_end:
        call = sub.step if rng.random() < 0.8 else sub.get_attr
        arg = a if call == sub.step else "poses"
        try:
            try:
                signal.setitimer(signal.ITIMER_REAL, rng.uniform(0.0001, 0.005))
                call(arg)
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
        except RAISED:
            hits += 1
        sub.step(a)  # after an interrupted call: the next one works
    # in step with its commands: reset and a step give the one-process numbers
    r_sub, r_one = sub.reset(seed=3), one.reset(seed=3)
    assert np.array_equal(r_sub[0], r_one[0])
    act = rng.uniform(-1, 1, (8, 4, 3))
    assert np.array_equal(sub.step(act)[0], one.step(act)[0])
    sub.close()
    print("ok", hits)
"""


@pytest.mark.parametrize("raised", ["ctrl-c", "timeout", "custom"])
def test_calls_interrupted_at_random_moments_leave_the_protocol_in_step(tmp_path, raised):
    """Ctrl-C (here: a timer raising KeyboardInterrupt) lands anywhere in a call, also
    while a message is on the pipe: the next call neither hangs nor reads a stale or
    half-read answer (before: a hang in the answer count, or a worker reported dead).
    So does an alarm-based timeout whose handler raises ``TimeoutError`` (an ``OSError``,
    which the pipe code had taken for a dead worker: red team 25) or another exception
    (after which the env had refused to step until ``reset()``): the caller gets its own
    exception and the env steps on."""
    import subprocess
    import sys

    script = tmp_path / "interrupted.py"
    script.write_text(_INTERRUPTED)
    for seed in (0, 1) if raised == "ctrl-c" else (0,):
        done = subprocess.run(
            [sys.executable, str(script), str(seed), raised],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0, done.stderr[-2000:]
        ok, hits = done.stdout.split()
        assert ok == "ok" and int(hits) > 20  # the interrupts did land


def _none(n: int):
    return None


def test_unpicklable_arguments_and_non_envs_are_value_errors():
    """An argument that cannot reach the workers is a ValueError and the env keeps
    serving (before: every later call blocked forever); a make_vector that returns no
    vector env is a ValueError (before: AttributeError)."""
    make = functools.partial(build_raw_vector_env, config=make_config(n_agents=N))
    with SubprocVectorEnv(make, 2, 2) as sub:
        sub.reset(seed=0)
        with pytest.raises(ValueError, match="picklable"):
            sub.set_attr("callback", lambda obs: obs)
        with pytest.raises(ValueError, match="picklable"):
            sub.reset(seed=1, options={"callback": lambda: 0})
        assert sub.step(np.zeros((2, N, 3)))[0].shape[:2] == (2, N)
        np.testing.assert_array_equal(sub.num_steps, [1, 1])
    with pytest.raises(ValueError, match=r"must return a vector env, got None"):
        SubprocVectorEnv(_none, 2, 2)


def test_bad_arguments_and_worker_failures_raise_clear_errors():
    make = functools.partial(build_raw_vector_env, config=make_config(n_agents=N))
    for workers in (0, 4, True, 1.5, None):
        with pytest.raises(ValueError, match="workers"):
            SubprocVectorEnv(make, 3, workers)
    with pytest.raises(ValueError, match="num_envs"):
        SubprocVectorEnv(make, 0, 1)
    with pytest.raises(ValueError, match="picklable"):
        SubprocVectorEnv(lambda n: make(n), 2, 2)
    with pytest.raises(ValueError, match="callable"):
        SubprocVectorEnv(3, 2, 2)
    with pytest.raises(ValueError, match="start_method"):
        SubprocVectorEnv(make, 2, 2, start_method="fork")
    with pytest.raises(ValueError, match="bad shard of 1 copies"):
        SubprocVectorEnv(_raise_value_error, 2, 2)
    with pytest.raises(RuntimeError, match="KeyError"):
        SubprocVectorEnv(_raise_key_error, 2, 2)
    with pytest.raises(ValueError, match="copies"):
        SubprocVectorEnv(_wrong_size, 2, 2)
    # a ConfigError in a worker comes back as a ConfigError (as in one process), with its
    # message; it was rebuilt as a plain ValueError, which `except ConfigError` missed
    bad_filter = functools.partial(
        build_filtered_vector_env,
        config=make_config(n_agents=N),
        tracker_params={"n_particles_total": 0},
    )
    with pytest.raises(ConfigError, match="n_particles_total"):
        SubprocVectorEnv(bad_filter, 2, 2)
    with pytest.raises(ValueError, match="n_particles_total") as plain:
        bad_filter(2)
    assert type(plain.value) is ConfigError
    with pytest.raises(ValueError, match="workers"):
        fov_coverage_v0.vector_env(num_envs=2, workers=0)

    sub = SubprocVectorEnv(make, 3, 2)
    try:
        with pytest.raises(ValueError, match="before reset"):
            sub.step(np.zeros((3, N, 3)))
        sub.reset(seed=0)
        with pytest.raises(ValueError, match=r"shape \(num_envs, n_agents, 3\)"):
            sub.step(np.zeros((2, N, 3)))
        bad = np.zeros((3, N, 3))
        bad[2, 1, 0] = np.nan
        with pytest.raises(ValueError, match=r"actions\[2, 1\]"):
            sub.step(bad)
        with pytest.raises(ValueError, match="sequence of num_envs = 3"):
            sub.reset(seed=[1, 2])
        with pytest.raises(ValueError, match="seed"):
            sub.reset(seed=-1)
        # a bad entry is named by its copy, before any shard resets
        steps_before = sub.num_steps
        with pytest.raises(ValueError, match=r"seed\[2\]"):
            sub.reset(seed=[0, 1, -1])
        np.testing.assert_array_equal(sub.num_steps, steps_before)
        # an error inside a worker: raised here, and the shard keeps serving
        with pytest.raises(AttributeError, match="no_such_method"):  # as SB3 expects
            sub.call("no_such_method")
        with pytest.raises(RuntimeError, match="TypeError"):  # others carry the traceback
            sub.call("state", 1, 2)
        sub.step(np.zeros((3, N, 3)))
        # a worker that dies: the next call says so
        os.kill(sub._procs[1].pid, signal.SIGKILL)
        sub._procs[1].join(timeout=10)
        with pytest.raises(RuntimeError, match="worker 1") as died:
            sub.step(np.zeros((3, N, 3)))
        assert "__main__" not in str(died.value)  # that hint is for a worker never built
    finally:
        assert not sub.closed
        sub.close()
    sub.close()  # idempotent
    assert sub.closed
    with pytest.raises(ValueError, match="closed"):
        sub.reset(seed=0)
    assert all(not p.is_alive() for p in sub._procs)


def _no_room_after_first_reset(n: int):
    """A shard of n copies whose random starts fail after the first reset (the 2-copy
    shard only): a finished copy there cannot reset."""
    import fov_marl.envs.core as core

    env = build_raw_vector_env(n, config=make_config(n_agents=2, max_cycles=2))
    if n == 2:
        place, calls = core.sample_initial_poses, [0]

        def flaky(config, rng):
            calls[0] += 1
            if calls[0] > 2:
                raise ValueError("no room")
            return place(config, rng)

        core.sample_initial_poses = flaky
    return env


def test_a_shard_that_fails_stops_every_shard_until_reset():
    """Red team: after one worker's automatic reset failed, each retried step raised
    there while the healthy worker stepped (and reset) again: the batch drifted apart."""
    from fov_marl.validation import ConfigError

    with SubprocVectorEnv(_no_room_after_first_reset, 3, 2) as sub:
        sub.reset(seed=0)
        a = np.zeros((3, 2, 3))
        sub.step(a)
        with pytest.raises(ConfigError, match="no room"):
            sub.step(a)  # every copy ends here; the 2-copy shard cannot reset
        steps = sub.num_steps
        for _ in range(2):
            with pytest.raises(ValueError, match=r"last step\(\) failed in a worker"):
                sub.step(a)
            np.testing.assert_array_equal(sub.num_steps, steps)  # nobody stepped on
        with pytest.raises(ConfigError, match="no room"):
            sub.reset(seed=0)
        with pytest.raises(ValueError, match=r"last reset\(\) failed"):
            sub.step(a)
