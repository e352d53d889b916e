"""VectorTrackerBank: B env copies in one set of arrays, bit-identical to B TrackerBanks."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.estimation import BankEstimate, TrackerBank, TrackerParams, VectorTrackerBank


def _obs(env, obs):
    return np.stack([np.asarray(obs[a], dtype=np.float32) for a in env.possible_agents])


def _assert_bank_equal(vec: VectorTrackerBank, banks: list[TrackerBank]) -> None:
    ev = vec.estimate()
    N = vec.n_agents
    for k, bank in enumerate(banks):
        eb = bank.estimate()
        for f in fields(BankEstimate):
            a, b = getattr(ev, f.name), getattr(eb, f.name)
            if isinstance(b, np.ndarray):
                np.testing.assert_array_equal(a[k * N : (k + 1) * N], b, err_msg=f.name)
        pv, ov = vec.particles_all()
        # the owner-free copy the safety rows read is the same array
        np.testing.assert_array_equal(vec.positions_all(), pv)
        for i in range(N):
            pb, ob = bank.particles_body(i)
            np.testing.assert_array_equal(pv[k * N + i], pb)
            np.testing.assert_array_equal(ov[k * N + i], ob)
            p1, o1 = vec.particles_body(k * N + i)
            np.testing.assert_array_equal(p1, pb)
            np.testing.assert_array_equal(o1, ob)
        assert vec.time_s[k] == eb.time_s


def _step_envs(envs, act):
    """Step every env copy with its rows of ``act (B, N, 3)``; ``(B, N, D)`` observations."""
    obs = [
        e.step({a: act[k, i] for i, a in enumerate(e.possible_agents)})[0]
        for k, e in enumerate(envs)
    ]
    return np.stack([_obs(e, x) for e, x in zip(envs, obs, strict=True)])


def _assert_banks_identical(a: VectorTrackerBank, b: VectorTrackerBank, t: int) -> None:
    """Every estimate field and every particle of two vector banks, bit for bit."""
    ea, eb = a.estimate(), b.estimate()
    for f in fields(BankEstimate):
        x, y = getattr(ea, f.name), getattr(eb, f.name)
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=f"step {t}: {f.name}")
    np.testing.assert_array_equal(a.particles_all()[0], b.particles_all()[0])


@pytest.mark.parametrize(
    "scenario,model,known",
    [("coverage", "mixture", True), ("crossing", "crossing", True), ("coverage", "static", False)],
)
def test_vector_bank_equals_separate_banks_bit_for_bit(scenario, model, known):
    mod = fov_coverage_v0 if scenario == "coverage" else fov_crossing_v0
    B, N, seed = 3, 5, 40
    envs = [mod.parallel_env(n_agents=N) for _ in range(B)]
    cfg = envs[0].unwrapped.config
    params = TrackerParams(motion_model=model, n_particles_total=300)
    obs = [e.reset(seed=seed + k)[0] for k, e in enumerate(envs)]
    poses = np.stack([e.unwrapped.poses for e in envs])
    vec = VectorTrackerBank(cfg, params, n_copies=B)
    vec.reset(
        np.stack([_obs(e, o) for e, o in zip(envs, obs, strict=True)]),
        initial_poses_world=poses if known else None,
        seeds=[seed + k for k in range(B)],
    )
    banks = []
    for k, e in enumerate(envs):
        bk = TrackerBank(cfg, params, seed=seed + k)
        bk.reset(_obs(e, obs[k]), initial_poses_world=poses[k] if known else None)
        banks.append(bk)
    _assert_bank_equal(vec, banks)
    rng = np.random.default_rng(0)
    for t in range(12):
        act = rng.uniform(-1, 1, (B, N, 3)).astype(np.float32)
        o = _step_envs(envs, act)
        vec.step(act, o)
        for k, bk in enumerate(banks):
            bk.step(act[k], o[k])
        if t == 6:  # copy 1 starts a new episode with a new seed; copy 0 and 2 go on
            o[1] = _obs(envs[1], envs[1].reset(seed=99)[0])
            poses[1] = envs[1].unwrapped.poses
            vec.reset_copies([1], o, initial_poses_world=poses if known else None, seeds=[99])
            banks[1] = TrackerBank(cfg, params, seed=99)
            banks[1].reset(o[1], initial_poses_world=poses[1] if known else None)
        _assert_bank_equal(vec, banks)
    assert vec.time_s[1] < vec.time_s[0]


def test_vector_bank_chunks_do_not_change_numbers(monkeypatch):
    """Rows split over several computation chunks (one chunk per 2 robots here)."""
    import fov_marl.estimation.tracker as T

    B, N = 2, 4
    env = fov_coverage_v0.parallel_env(n_agents=N)
    cfg = env.unwrapped.config
    params = TrackerParams(n_particles_total=200)
    obs = [fov_coverage_v0.parallel_env(n_agents=N).reset(seed=s)[0] for s in (1, 2)]
    o = np.stack([_obs(env, x) for x in obs])
    a = VectorTrackerBank(cfg, params, n_copies=B)
    a.reset(o, seeds=[1, 2])
    monkeypatch.setattr(T, "CHUNK_PARTICLES", 400)
    b = VectorTrackerBank(cfg, params, n_copies=B)
    assert len(b._bounds) == 4
    b.reset(o, seeds=[1, 2])
    b.reset_copies(np.array([False, True]), o, seeds=[2])
    act = np.zeros((B, N, 3))
    a.step(act, o)
    b.step(act, o)
    np.testing.assert_array_equal(a.estimate().mean_body, b.estimate().mean_body)
    np.testing.assert_array_equal(a.particles_all()[0], b.particles_all()[0])


def test_vector_bank_input_errors():
    env = fov_coverage_v0.parallel_env(n_agents=3)
    cfg = env.unwrapped.config
    with pytest.raises(ValueError, match="n_copies"):
        VectorTrackerBank(cfg, n_copies=0)
    vec = VectorTrackerBank(cfg, n_copies=2)
    D = vec._obs_size
    with pytest.raises(ValueError, match="before reset"):
        vec.step(np.zeros((2, 3, 3)), np.zeros((2, 3, D)))
    with pytest.raises(ValueError, match="obs must have shape"):
        vec.reset(np.zeros((2, 3, D + 1)))
    with pytest.raises(ValueError, match="seeds must hold 2"):
        vec.reset(np.zeros((2, 3, D)), seeds=[1])
    with pytest.raises(ValueError, match="initial_poses_world"):
        vec.reset(np.zeros((2, 3, D)), initial_poses_world=np.zeros((3, 3)))
    vec.reset(np.zeros((2, 3, D)), seeds=[0, 1])
    with pytest.raises(ValueError, match="actions must be finite"):
        vec.step(np.full((2, 3, 3), np.nan), np.zeros((2, 3, D)))
    with pytest.raises(ValueError, match="copies must be distinct"):
        vec.reset_copies([2], np.zeros((2, 3, D)))
    with pytest.raises(ValueError, match="row must be"):
        vec.particles_body(6)


@pytest.mark.parametrize("n_threads", [2, 3])
def test_threaded_bank_equals_serial_bit_for_bit(n_threads, monkeypatch):
    """Chunks stepped on several threads give the serial bank's numbers (closed loop of
    20 steps with detections, a restarted copy, and at least one chunk per thread)."""
    import fov_marl.estimation.tracker as T

    monkeypatch.setattr(T, "CHUNK_PARTICLES", 600)  # 2 robots per chunk at P_T = 300
    B, N = 3, 5
    envs = [fov_coverage_v0.parallel_env(n_agents=N) for _ in range(B)]
    cfg = envs[0].unwrapped.config
    params = TrackerParams(n_particles_total=300)
    obs = [e.reset(seed=70 + k)[0] for k, e in enumerate(envs)]
    o = np.stack([_obs(e, x) for e, x in zip(envs, obs, strict=True)])
    poses = np.stack([e.unwrapped.poses for e in envs])
    serial = VectorTrackerBank(cfg, params, n_copies=B)
    threaded = VectorTrackerBank(cfg, params, n_copies=B, n_threads=n_threads)
    assert threaded.n_threads == n_threads and len(threaded._bounds) >= n_threads
    for bank in (serial, threaded):
        bank.reset(o, initial_poses_world=poses, seeds=[70, 71, 72])
    rng = np.random.default_rng(3)
    n_det = 0
    for t in range(20):
        act = rng.uniform(-1, 1, (B, N, 3)).astype(np.float32)
        o = _step_envs(envs, act)
        serial.step(act, o)
        threaded.step(act, o)
        if t == 9:
            o[2] = _obs(envs[2], envs[2].reset(seed=5)[0])
            for bank in (serial, threaded):
                bank.reset_copies([2], o, seeds=[5])
        n_det += int(serial.estimate().detected.sum())
        _assert_banks_identical(serial, threaded, t)
    assert n_det > 0  # the update's detection branch ran


@pytest.mark.parametrize("model", ["mixture", "static"])
def test_draws_ahead_give_the_inline_numbers(model, monkeypatch):
    """Serial chunks whose next chunk's prediction noise is drawn on a helper thread
    (``DRAW_AHEAD``) give the numbers of inline draws, bit for bit: closed loop of 20
    steps with detections, recoveries and a restarted copy, 4+ chunks."""
    import fov_marl.estimation.tracker as T

    monkeypatch.setattr(T, "CHUNK_PARTICLES", 600)  # 2 robots per chunk at P_T = 300
    B, N = 3, 5
    envs = [fov_coverage_v0.parallel_env(n_agents=N) for _ in range(B)]
    cfg = envs[0].unwrapped.config
    params = TrackerParams(motion_model=model, n_particles_total=300)
    obs = [e.reset(seed=80 + k)[0] for k, e in enumerate(envs)]
    o = np.stack([_obs(e, x) for e, x in zip(envs, obs, strict=True)])
    poses = np.stack([e.unwrapped.poses for e in envs])
    inline = VectorTrackerBank(cfg, params, n_copies=B)
    ahead = VectorTrackerBank(cfg, params, n_copies=B)
    assert len(ahead._bounds) >= 4 and ahead.n_threads == 1
    for bank in (inline, ahead):
        bank.reset(o, initial_poses_world=poses, seeds=[80, 81, 82])
    drawn = []
    real_draw = T._BankCore.draw_step_noise

    def counted(core):
        drawn.append(core)
        real_draw(core)

    monkeypatch.setattr(T._BankCore, "draw_step_noise", counted)
    rng = np.random.default_rng(5)
    n_det = n_rec = 0
    for t in range(20):
        act = rng.uniform(-1, 1, (B, N, 3)).astype(np.float32)
        o = _step_envs(envs, act)
        monkeypatch.setattr(T, "DRAW_AHEAD", False)
        inline.step(act, o)
        monkeypatch.setattr(T, "DRAW_AHEAD", True)
        drawn.clear()
        ahead.step(act, o)
        # every chunk drew once: the first inline, the others on the helper
        assert sorted(map(id, drawn)) == sorted(map(id, ahead._cores))
        if t == 9:
            o[1] = _obs(envs[1], envs[1].reset(seed=6)[0])
            for bank in (inline, ahead):
                bank.reset_copies([1], o, seeds=[6])
        ei = inline.estimate()
        n_det += int(ei.detected.sum())
        n_rec += int(ei.recovered.sum())
        _assert_banks_identical(inline, ahead, t)
    assert n_det > 0 and n_rec > 0  # the detection and recovery branches ran


def test_draws_ahead_end_before_a_chunks_error_reaches_the_caller(monkeypatch):
    """A chunk that raises while the helper draws the next chunk's noise: the caller gets
    the chunk's exception only once the helper has finished (no draw outlives the step)."""
    import threading
    import time

    import fov_marl.estimation.tracker as T

    monkeypatch.setattr(T, "CHUNK_PARTICLES", 400)
    env = fov_coverage_v0.parallel_env(n_agents=4)
    obs = _obs(env, env.reset(seed=1)[0])
    bank = TrackerBank(env.unwrapped.config, TrackerParams(n_particles_total=200), seed=4)
    assert len(bank._bounds) >= 2 and bank.n_threads == 1
    bank.reset(obs)
    finished = threading.Event()

    def slow_draw(core):
        time.sleep(0.2)
        finished.set()

    def boom(core, act, obs_arr, drawn=False):
        raise FloatingPointError("chunk failed")

    monkeypatch.setattr(T._BankCore, "draw_step_noise", slow_draw)
    monkeypatch.setattr(T._BankCore, "step", boom)
    with pytest.raises(FloatingPointError, match="chunk failed"):
        bank.step(np.zeros((4, 3)), obs)
    assert finished.is_set()


def test_tracker_bank_threads_and_their_errors(monkeypatch):
    import fov_marl.estimation.tracker as T

    env = fov_coverage_v0.parallel_env(n_agents=4)
    cfg = env.unwrapped.config
    obs = _obs(env, env.reset(seed=1)[0])
    monkeypatch.setattr(T, "CHUNK_PARTICLES", 400)
    params = TrackerParams(n_particles_total=200)
    a = TrackerBank(cfg, params, seed=4)
    b = TrackerBank(cfg, params, seed=4, n_threads=2)
    for bank in (a, b):
        bank.reset(obs)
        bank.step(np.full((4, 3), 0.5), obs)
    np.testing.assert_array_equal(a.estimate().mean_body, b.estimate().mean_body)
    for bad in (0, 1.5, True, "2", 2000):
        with pytest.raises(ValueError, match=r"n_threads must be an integer in \[1, 1024\]"):
            TrackerBank(cfg, params, n_threads=bad)
        with pytest.raises(ValueError, match=r"n_threads must be an integer in \[1, 1024\]"):
            VectorTrackerBank(cfg, params, n_copies=2, n_threads=bad)

    # an error inside one chunk's step reaches the caller from the worker thread
    def boom(self, act, obs_arr):
        raise FloatingPointError("chunk failed")

    monkeypatch.setattr(T._BankCore, "step", boom)
    with pytest.raises(FloatingPointError, match="chunk failed"):
        b.step(np.zeros((4, 3)), obs)


def _forked_step(conn) -> None:  # runs in a forked child
    env = fov_coverage_v0.parallel_env(n_agents=4)
    obs = _obs(env, env.reset(seed=2)[0])
    bank = TrackerBank(
        env.unwrapped.config, TrackerParams(n_particles_total=200), seed=1, n_threads=2
    )
    bank.reset(obs)
    bank.step(np.full((4, 3), 0.3), obs)
    conn.send_bytes(bank.estimate().mean_body.tobytes())
    conn.close()


def test_threaded_bank_in_a_forked_child(monkeypatch):
    """A child forked after the parent's pool exists gets a pool of its own (the parent's
    worker threads do not exist in the child: submitting to them would hang)."""
    import multiprocessing as mp

    import fov_marl.estimation.tracker as T

    if "fork" not in mp.get_all_start_methods():
        pytest.skip("no fork on this platform")
    monkeypatch.setattr(T, "CHUNK_PARTICLES", 400)
    env = fov_coverage_v0.parallel_env(n_agents=4)
    obs = _obs(env, env.reset(seed=2)[0])
    bank = TrackerBank(
        env.unwrapped.config, TrackerParams(n_particles_total=200), seed=1, n_threads=2
    )
    bank.reset(obs)
    bank.step(np.full((4, 3), 0.3), obs)  # the parent's pool now exists
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_forked_step, args=(send,))
    child.start()
    got = recv.recv_bytes() if recv.poll(60) else None
    child.join(10)
    if child.is_alive():
        child.kill()
    assert got is not None, "the forked child hung stepping a threaded bank"
    assert child.exitcode == 0
    assert got == bank.estimate().mean_body.tobytes()
