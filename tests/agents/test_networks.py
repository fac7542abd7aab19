import jax
import jax.numpy as jnp

from jarena.core.spec import Box
from jarena_agents import networks


def test_actor_critic_value_mlp_has_its_own_layers():
    net = networks.ActorCritic(Box(-1.0, 1.0, (2,)), hidden=(8,), value_hidden=(16, 16))
    params = net.init(jax.random.key(0), jnp.zeros((3, 5)))["params"]
    assert [params["actor"][f"Dense_{i}"]["kernel"].shape for i in range(2)] == [(5, 8), (8, 2)]
    assert [params["critic"][f"Dense_{i}"]["kernel"].shape for i in range(3)] == [(5, 16), (16, 16), (16, 1)]
    (mean, log_std), value = net.apply({"params": params}, jnp.zeros((3, 5)))
    assert mean.shape == log_std.shape == (3, 2) and value.shape == (3,)
    shared = networks.ActorCritic(Box(-1.0, 1.0, (2,)), hidden=(8,)).init(jax.random.key(0), jnp.zeros((3, 5)))
    assert shared["params"]["critic"]["Dense_0"]["kernel"].shape == (5, 8)  # default: the policy's layers
