import jax
import jax.numpy as jnp
import pytest

import jarena
import jarena_agents
from jarena_agents import ConfigError


def test_registry_and_errors():
    assert {"random", "no_op", "oracle_cartpole", "oracle_pendulum"} <= set(jarena_agents.list_agents())
    with pytest.raises(KeyError, match="unknown agent 'randmo' \\(did you mean 'random'\\?\\)"):
        jarena_agents.build_agent("randmo")
    with pytest.raises(ConfigError, match="unknown config key\\(s\\) \\['gain'\\].*valid keys: \\['k_theta'"):
        jarena_agents.build_agent("oracle_cartpole", {"gain": 1.0})
    with pytest.raises(ConfigError, match="must be a float"):
        jarena_agents.build_agent("oracle_cartpole", {"k_theta": "big"})


def test_random_agent_acts_in_spec_batched():
    arena = jarena.build_arena("classic|domain:cartpole")
    agent = jarena_agents.build_agent("random")
    state = agent.init(jax.random.key(0), arena.spec, 16)
    _, info = jarena.batch_reset(arena, jax.random.key(0), 16)
    action, _ = jax.jit(agent.act)(state, info, jax.random.key(1), None)
    assert action.shape == (16,) and bool(jnp.all((action >= 0) & (action < 2)))
    assert len(set(action.tolist())) == 2


def test_cartpole_oracle_reaches_success():
    arena = jarena.build_arena("classic|domain:cartpole,task:balance")
    result = jarena.evaluate(jarena_agents.build_agent("oracle_cartpole"), arena, jax.random.key(0))
    assert result.summary()["success_rate"] == 1.0
    assert result.summary()["return_mean"] == 500.0
    random = jarena.evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(0))
    assert random.summary()["return_mean"] < 50


def test_pendulum_oracle_swings_up_and_stabilises():
    arena = jarena.build_arena("classic|domain:pendulum,task:swingup")
    oracle = jarena.evaluate(jarena_agents.build_agent("oracle_pendulum"), arena, jax.random.key(0))
    assert oracle.summary()["success_rate"] == 1.0
    assert oracle.summary()["return_mean"] > -200
    random = jarena.evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(0))
    assert random.summary()["return_mean"] < -800
