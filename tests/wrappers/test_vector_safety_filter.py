"""VectorSafetyFilterWrapper: the same actions as B per-copy SafetyFilterWrappers.

``LoopVectorEnv`` is a small reference vector env (the conventions of issue 12: copy k
reset with seed s + k, SAME-STEP autoreset with ``final_obs`` / ``_final_obs``) built by
looping over B ParallelEnvs; the real batched env replaces it at merge.
"""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.envs import fov_coverage_v0, fov_crossing_v0
from fov_marl.infos import safety_of
from fov_marl.wrappers import SafetyFilterWrapper, VectorSafetyFilterWrapper


class LoopVectorEnv:
    """Reference vector env over B ParallelEnvs (same-step autoreset)."""

    def __init__(self, module, num_envs: int, **config) -> None:
        self.envs = [module.parallel_env(**config) for _ in range(num_envs)]
        self.num_envs = num_envs
        base = self.envs[0].unwrapped
        self.config = base.config
        self.n_agents = self.config.n_agents
        self.possible_agents = list(base.possible_agents)
        self.single_observation_space = base.observation_space(self.possible_agents[0])
        self.single_action_space = base.action_space(self.possible_agents[0])

    def _stack(self, obs: dict) -> np.ndarray:
        return np.stack([obs[a] for a in self.possible_agents]).astype(np.float32)

    @property
    def poses(self) -> np.ndarray:
        return np.stack([e.unwrapped.poses for e in self.envs])

    def reset(self, seed=None, options=None):
        out = []
        for k, e in enumerate(self.envs):
            o, _ = e.reset(seed=None if seed is None else seed + k, options=options)
            out.append(self._stack(o))
        return np.stack(out), {}

    def step(self, actions):
        B, N = self.num_envs, self.n_agents
        obs = np.zeros((B, N, self.single_observation_space.shape[0]), dtype=np.float32)
        rew = np.zeros((B, N), dtype=np.float32)
        term = np.zeros((B, N), dtype=bool)
        trunc = np.zeros((B, N), dtype=bool)
        final = np.zeros_like(obs)
        done = np.zeros(B, dtype=bool)
        for k, e in enumerate(self.envs):
            act = {a: actions[k, i] for i, a in enumerate(self.possible_agents)}
            o, r, te, tr, _ = e.step(act)
            obs[k] = self._stack(o)
            for i, a in enumerate(self.possible_agents):
                rew[k, i], term[k, i], trunc[k, i] = r[a], te[a], tr[a]
            if not e.agents:
                done[k] = True
                final[k] = obs[k]
                o2, _ = e.reset()
                obs[k] = self._stack(o2)
        return obs, rew, term, trunc, {"final_obs": final, "_final_obs": done}

    def close(self) -> None:
        for e in self.envs:
            e.close()


@pytest.mark.parametrize(
    "module,n,controller,threads",
    [
        (fov_coverage_v0, 4, "auto", 1),
        (fov_crossing_v0, 4, "batched", 1),
        (fov_coverage_v0, 3, "loop", 1),
        # the tracker's chunks on 2 threads (2 chunks of 6 robots): the same actions
        (fov_coverage_v0, 4, "batched", 2),
    ],
)
def test_vector_filter_equals_per_copy_filters(module, n, controller, threads):
    B, seed, T, cycles = 3, 7, 30, 12  # episodes end (and copies restart) twice
    kw = dict(n_agents=n, max_cycles=cycles, arena_size_m=12.0)  # dense: the filter acts
    if module is fov_crossing_v0:
        kw["crossing_radius_m"] = 4.0
    venv = VectorSafetyFilterWrapper(
        LoopVectorEnv(module, B, **kw), controller=controller, tracker_threads=threads
    )
    refs = [SafetyFilterWrapper(module.parallel_env(**kw)) for _ in range(B)]
    obs, _ = venv.reset(seed=seed)
    assert len(venv.pipeline.bank._cores) == threads
    ref_obs = [r.reset(seed=seed + k)[0] for k, r in enumerate(refs)]
    for k in range(B):
        np.testing.assert_array_equal(
            obs[k], np.stack([ref_obs[k][a] for a in venv.possible_agents])
        )
    agents = venv.possible_agents
    rng = np.random.default_rng(1)
    n_done = 0
    n_intervened = 0
    for t in range(T):
        act = rng.uniform(-1, 1, (B, n, 3)).astype(np.float32)
        obs, rew, term, trunc, infos = venv.step(act)
        s = infos["safety"]
        for k, ref in enumerate(refs):
            o, r, te, tr, inf = ref.step({a: act[k, i] for i, a in enumerate(agents)})
            applied = np.stack([safety_of(inf[a])["applied_action"] for a in agents])
            np.testing.assert_allclose(s["applied_action"][k], applied, atol=1e-6, err_msg=f"t{t}")
            for key in ("intervened", "status", "fallback", "cause_bits"):
                np.testing.assert_array_equal(
                    s[key][k], [safety_of(inf[a])[key] for a in agents], err_msg=key
                )
            np.testing.assert_array_equal(
                s["nominal_action"][k],
                np.stack([safety_of(inf[a])["nominal_action"] for a in agents]),
            )
            n_intervened += int(s["intervened"][k].sum())
            if not ref.env.agents:  # the reference copy finished: restart it like the vector env
                n_done += 1
                assert infos["_final_obs"][k]
                np.testing.assert_array_equal(
                    infos["final_obs"][k], np.stack([o[a] for a in agents])
                )
                o, _ = ref.reset()
            np.testing.assert_array_equal(obs[k], np.stack([o[a] for a in agents]))
    assert n_done == 2 * B
    assert n_intervened > 0


def test_vector_filter_api_and_errors():
    venv = VectorSafetyFilterWrapper(LoopVectorEnv(fov_coverage_v0, 2, n_agents=3))
    assert venv.num_envs == 2 and venv.n_agents == 3
    assert venv.single_action_space.shape == (3,)
    with pytest.raises(ValueError, match="before reset"):
        venv.step(np.zeros((2, 3, 3)))
    _, infos = venv.reset(seed=0)
    # reset reports the neutral filter state, as the per-copy wrapper's reset() does
    assert (infos["safety"]["status"] == "reset").all()
    assert infos["safety"]["cause_bits"].shape == (2, 3) and not infos["safety"]["cause_bits"].any()
    assert not infos["safety"]["intervened"].any() and not infos["safety"]["fallback"].any()
    assert infos["safety"]["applied_action"].shape == (2, 3, 3)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match=r"finite.*actions\[0, 0\]"):
        venv.step(np.full((2, 3, 3), np.nan))
    # the raw vector env's checks: bool, complex, str and object actions are refused
    # (they were accepted here, complex ones losing their imaginary part)
    for bad in (
        np.zeros((2, 3, 3), bool),
        np.zeros((2, 3, 3), complex),
        np.full((2, 3, 3), "0.5"),
        np.zeros((2, 3, 3), object),
    ):
        with pytest.raises(ValueError, match="actions must be a real"):
            venv.step(bad)
    _, _, _, _, infos = venv.step(np.zeros((2, 3, 3)))
    assert infos["safety"]["applied_action"].shape == (2, 3, 3)
    assert infos["safety"]["status"].shape == (2, 3)
    assert venv.last_cpu_s > 0
    with pytest.raises(ValueError, match="vector env"):
        VectorSafetyFilterWrapper(object())
    with pytest.raises(ValueError, match=r"tracker_threads must be an integer in \[1, 1024\]"):
        VectorSafetyFilterWrapper(LoopVectorEnv(fov_coverage_v0, 1, n_agents=3), tracker_threads=0)
    with pytest.raises(ValueError, match="controller_params"):
        VectorSafetyFilterWrapper(
            LoopVectorEnv(fov_coverage_v0, 1, n_agents=3), controller_params={"nope": 1}
        )
    venv.close()
