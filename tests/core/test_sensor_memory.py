"""Sensors with memory: ``frame_stack`` over a sensor, through reset, step, auto-reset, jit and vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.spec import Box, Dict
from jarena.sensors import frame_stack
from jarena.tasks.time_limit import time_limit


def counter_arena(k, limit=5):
    """Physics: a counter that adds the action; the sensor draws it into a 2 x 2 x 1 image and a vector."""
    dynamics = Dynamics(init=lambda key, params: jnp.zeros((), jnp.float32), step=lambda x, u, p: x + u[0],
                        control_spec=Box(-10.0, 10.0, (1,)))
    sensor = Sensor(observe=lambda x, params: {"pixels": jnp.full((2, 2, 1), x, jnp.float32),
                                               "value": jnp.stack([x, -x])},
                    spec=Dict(pixels=Box(-100.0, 100.0, (2, 2, 1)), value=Box(-100.0, 100.0, (2,))))
    return jarena.Arena(dynamics=dynamics, sensor=frame_stack(sensor, k, ("pixels", "value")),
                        task=jarena.chain(time_limit(limit)))


def test_frames_stack_oldest_first_and_restart_each_episode():
    arena = counter_arena(3)
    spec = arena.observation_spec
    assert spec["pixels"].shape == (2, 2, 3) and spec["value"].shape == (2, 3)
    state, info = arena.reset(jax.random.key(0))
    np.testing.assert_array_equal(info.observation["pixels"][0, 0], [0, 0, 0])  # the first frame, three times
    step = jax.jit(arena.step)
    seen = []
    for u in (1.0, 2.0, 4.0):
        state, info = step(state, jnp.array([u]))
        seen.append(np.asarray(info.observation["pixels"][1, 1]))
    np.testing.assert_array_equal(seen, [[0, 0, 1], [0, 1, 3], [1, 3, 7]])
    np.testing.assert_array_equal(info.observation["value"], [[1, 3, 7], [-1, -3, -7]])
    assert bool(spec.contains(info.observation))
    # under auto-reset a finished episode's last stack is in info.final, the next episode starts afresh
    states, infos = jarena.batch_reset(arena, jax.random.key(1), 2)
    batch_step = jax.jit(lambda s, a: jarena.batch_step(arena, s, a))
    for _ in range(5):
        states, infos = batch_step(states, jnp.ones((2, 1)))
    np.testing.assert_array_equal(infos.final.observation["pixels"][0, 0, 0], [3, 4, 5])
    np.testing.assert_array_equal(infos.observation["pixels"][0, 0, 0], [0, 0, 0])


def test_frame_stack_checks_its_arguments():
    sensor = Sensor(observe=lambda x, p: {"pixels": jnp.zeros((2, 2, 3))}, spec=Dict(pixels=Box(0, 1, (2, 2, 3))))
    assert frame_stack(sensor, 1) is sensor
    with pytest.raises(ValueError, match="positive number of frames, got 0"):
        frame_stack(sensor, 0)
    with pytest.raises(ValueError, match=r"observes no \['depth'\]; its keys: pixels"):
        frame_stack(sensor, 2, ("depth",))


def test_pixel_arena_stacks_frames():
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup,pixels:16,state:false,frame_stack:3")
    assert arena.observation_spec["pixels"] == Box(0, 255, (16, 16, 9), jnp.uint8)
    state, info = jax.jit(arena.reset)(jax.random.key(0))
    np.testing.assert_array_equal(info.observation["pixels"][..., :3], info.observation["pixels"][..., 6:])
    step = jax.jit(arena.step)
    first = info.observation["pixels"][..., 6:]
    stacks = []
    for _ in range(30):
        state, info = step(state, jnp.array([1.0]))
        stacks.append(np.asarray(info.observation["pixels"]))
    np.testing.assert_array_equal(stacks[1][..., :3], first)
    np.testing.assert_array_equal(stacks[-1][..., :3], stacks[-3][..., 6:])
    assert not np.array_equal(stacks[-1][..., 6:], first)  # the cart moved
    with pytest.raises(jarena.ArenaStringError, match="frame_stack need pixels"):
        jarena.build_arena("dmc|domain:cartpole,frame_stack:3")
