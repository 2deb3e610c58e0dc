"""The PPO policies evaluated the same on every CPU (agents.ppo.network): the float64 network is the
trained one, its sums run in the documented order, and acting touches neither torch nor numpy's
vector kernels for the elementary functions, nor BLAS."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import risk_env  # noqa: E402
from agents.ppo import PPOAgent, shipped_model  # noqa: E402
from agents.ppo.network import LIBM, PolicyNet, fixed_order_dot, scalar_map  # noqa: E402
from risk_env.models.dynamics import unicycle_step  # noqa: E402
from risk_env.models.ops import MATH  # noqa: E402

VARIANTS = ("penalty", "lagrangian", "lagrangian_two_crossing")


def _pairwise(terms: list[float]) -> float:
    """The documented order in plain Python: entry i added to entry i + n/2, an odd last carried."""
    while len(terms) > 1:
        half = len(terms) // 2
        paired = [terms[i] + terms[i + half] for i in range(half)]
        terms = paired + terms[2 * half :] if len(terms) % 2 else paired
    return terms[0]


def test_fixed_order_dot_sums_in_the_documented_order() -> None:
    # 1e16 + 1 rounds to 1e16: a left-to-right sum gives 1, the pairwise order (1e16 - 1e16) + (1 + 1) 2
    assert fixed_order_dot(np.array([[1e16, 1.0, -1e16, 1.0]]), np.ones((1, 4)))[0, 0] == 2.0
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 7, 29, 50, 64, 65):
        x, w = rng.normal(size=(3, n)) * 10.0 ** rng.integers(-8, 8, (3, n)), rng.normal(size=(5, n))
        got = fixed_order_dot(x, w)
        assert got.shape == (3, 5)
        for b in range(3):
            for i in range(5):
                assert got[b, i] == _pairwise((x[b] * w[i]).tolist())
                assert got[b, i] == pytest.approx(math.fsum((x[b] * w[i]).tolist()), rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("variant", VARIANTS)
def test_float64_network_is_the_trained_one(variant: str) -> None:
    """On random and on real features the float64 mean action is torch's float32 one to 1e-5."""
    agent = PPOAgent.load(shipped_model(variant))
    size = agent.policy.size
    seen = np.random.default_rng(1).normal(size=(500, size)).astype(np.float32)
    torch_action, _ = agent.model.predict(seen, deterministic=True)
    ours = agent.policy(seen)
    assert ours.dtype == np.float64 and ours.shape == (500, 2)
    np.testing.assert_allclose(np.clip(ours, -1.0, 1.0), torch_action, atol=1e-5)
    assert [w.shape[0] for w in agent.policy.weights] == [64, 64, 2]
    assert agent.policy.activations == ("Tanh", "Tanh")


def test_acting_uses_neither_torch_nor_numpys_vector_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    """The deterministic action of every shipped policy with torch's forward pass, numpy's sin, cos,
    tanh, hypot and its BLAS entry points all made to fail: the same inputs as before."""
    env = gym.make(risk_env.ENV_ID, uncertainty="high", object_motion="sampled", risk_tolerance=500.0)
    obs, _ = env.reset(seed=3)
    two = gym.make(risk_env.ENV_ID, scene="two_crossing").reset(seed=3)[0]
    agents = [PPOAgent.load(shipped_model(v), scenario=env.unwrapped.scenario) for v in VARIANTS[:2]]
    agents.append(PPOAgent.load(shipped_model(VARIANTS[2])))
    cases = [(agents[0], obs), (agents[1], np.stack([obs, obs])), (agents[2], two)]
    before = [agent.predict(o)[0] for agent, o in cases]

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("a CPU-dependent kernel was called")

    for name in ("sin", "cos", "tanh", "hypot", "dot", "matmul", "einsum", "inner"):
        monkeypatch.setattr(np, name, refuse)
    for agent, _ in cases:
        monkeypatch.setattr(agent.model.policy, "forward", refuse)
        monkeypatch.setattr(agent.model, "predict", refuse)
    for (agent, o), expected in zip(cases, before, strict=True):
        np.testing.assert_array_equal(agent.predict(o)[0], expected)
    monkeypatch.undo()
    # the sampled action still comes from SB3
    assert agents[0].predict(obs, deterministic=False)[0].shape == (2,)


def test_libm_face_takes_each_entry_from_math() -> None:
    """The features' elementary functions are Python's ``math`` ones entry by entry; the prediction
    steps the single env's dynamics (one float at a time) exactly."""
    a = np.random.default_rng(2).uniform(-10.0, 10.0, (3, 4))
    for face, fn in ((LIBM.sin, math.sin), (LIBM.cos, math.cos)):
        assert face(a).tolist() == [[fn(v) for v in row] for row in a.tolist()]
    assert LIBM.hypot(a, 2.0).tolist() == [[math.hypot(v, 2.0) for v in row] for row in a.tolist()]
    assert scalar_map(math.tanh, np.float64(0.5)).shape == ()
    state = np.random.default_rng(3).uniform(-1.0, 1.0, (5, 5))
    state[0, 4] = 0.0  # omega = 0: sinc's limit
    batched = unicycle_step(*state.T, 0.5, LIBM)
    for i, row in enumerate(state.tolist()):
        one = unicycle_step(*row, 0.5, MATH)
        assert [float(part[i]) for part in batched] == list(one)


def test_unsupported_networks_are_refused_by_name() -> None:
    from stable_baselines3 import PPO
    from torch import nn

    env = gym.make("Pendulum-v1")
    relu = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [8], "activation_fn": nn.ReLU}, device="cpu")
    net = PolicyNet.from_sb3(relu.policy)
    seen = np.random.default_rng(4).normal(size=(50, 3)).astype(np.float32)
    np.testing.assert_allclose(
        np.clip(net(seen), -2.0, 2.0), relu.predict(seen, deterministic=True)[0], atol=1e-5
    )
    elu = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [8], "activation_fn": nn.ELU}, device="cpu")
    with pytest.raises(ValueError, match="layer 1 is ELU"):
        PolicyNet.from_sb3(elu.policy)
