"""PPO from pixels: image observations go through the CNN torso, the rest through the vector path."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

import jarena
import jarena_agents
from jarena.core.spec import Box, Dict, Discrete, image_spec
from jarena.tasks.time_limit import time_limit
from jarena_agents import networks


@struct.dataclass
class Bandit:
    target: jax.Array  # int32: the side lit in the image, 0 (left) or 1 (right)
    key: jax.Array  # uint32 (2,): draws the next target


def pixel_bandit() -> jarena.Arena:
    """Each step shows an 8 x 8 image lit on the left or the right half; choosing that side earns 1.

    Only the image tells the side (the vector observation is a constant), so a policy above chance reads pixels.
    """
    def draw(key):
        key, sub = jax.random.split(key)
        return Bandit(jax.random.bernoulli(sub).astype(jnp.int32), key)

    dynamics = jarena.Dynamics(init=lambda key, params: draw(jax.random.key_data(key)),
                               step=lambda b, u, params: draw(b.key), control_spec=Discrete(2), name="bandit")

    def observe(b, params):
        lit = jnp.where((jnp.arange(8) < 4) == (b.target == 0), 255, 0).astype(jnp.uint8)
        return {"pixels": jnp.broadcast_to(lit[None, :, None], (8, 8, 1)), "bias": jnp.ones((1,), jnp.float32)}

    def update(state, outcome, transition, params):
        hit = transition.control == transition.previous.target
        return outcome.replace(reward=outcome.reward + hit.astype(jnp.float32)), state

    sensor = jarena.Sensor(observe=observe, spec=Dict(pixels=image_spec(8, 8, 1), bias=Box(1.0, 1.0, (1,))))
    return jarena.Arena(dynamics=dynamics, sensor=sensor, task=jarena.chain(jarena.Task(update=update), time_limit(8)),
                        name="pixel-bandit")


def test_image_keys_and_the_split_observation():
    arena = pixel_bandit()
    assert networks.image_keys(arena.spec) == ("pixels",)
    assert networks.vector_size(arena.spec, ("pixels",)) == 1
    states, info = jarena.batch_reset(arena, jax.random.key(0), 3)
    split = networks.split_observation(info, ("pixels",))
    assert split["vector"].shape == (3, 1) and split["images"]["pixels"].dtype == jnp.uint8


def test_ppo_learns_to_read_pixels():
    arena = pixel_bandit()
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 16, "rollout_length": 8, "minibatches": 2,
                                              "total_steps": 16 * 8 * 40, "learning_rate": 3e-3, "hidden": [32],
                                              "cnn": [[8, 3, 2], [8, 3, 1]], "normalize_observations": True})
    state = agent.init_training(jax.random.key(0), arena)
    assert "encoder" in state.params["params"]
    state, metrics = jax.jit(lambda s: agent.train(s, arena, 40))(state)
    returns = np.asarray(metrics["episode_return"])
    assert returns[0] < 5.5  # chance: 4 of 8
    assert returns[-3:].mean() > 7.0, returns
    # the trained policy, deterministic, reads the image
    policy = agent.policy(state, arena.spec)
    _, info = jarena.batch_reset(arena, jax.random.key(5), 64)
    actions, _ = agent.act(policy, info, jax.random.key(1))
    targets = (info.observation["pixels"][:, 0, 0, 0] == 0).astype(jnp.int32)  # left dark: right lit
    assert np.mean(np.asarray(actions) == np.asarray(targets)) > 0.9


def test_default_cnn_fits_64_pixel_images():
    images = {"pixels": jnp.zeros((2, 64, 64, 9), jnp.uint8)}
    for padding, side in (("VALID", 4), ("SAME", 8)):  # Nature DQN's: 64 -> 15 -> 6 -> 4; SAME: 16 -> 8 -> 8
        encoder = networks.PixelEncoder(padding=padding)
        params = encoder.init(jax.random.key(0), images)
        assert encoder.apply(params, images).shape == (2, side * side * 64)


def test_a_kernel_larger_than_its_input_is_a_clear_error():
    encoder = networks.PixelEncoder()
    images = {"pixels": jnp.zeros((1, 16, 16, 3), jnp.uint8)}  # 16 -> 3 after the first layer: 4 x 4 does not fit
    with pytest.raises(ValueError, match="layer 1's 4 x 4 kernel does not fit its 3 x 3 input"):
        encoder.init(jax.random.key(0), images)


def test_unknown_padding_names_the_choices():
    with pytest.raises(ValueError, match="cnn_padding 'same'.*VALID, SAME"):
        jarena_agents.build_agent("ppo", {"cnn_padding": "same"})
