"""``pixels`` options of the dmc builder: camera images in the observation, rendered on device every step."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas.mjx import camera
from jarena.arenas.mjx.dynamics import model_of
from jarena.building.grammar import ArenaStringError
from jarena.core.spec import Box, image_spec


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena("dmc|domain:cartpole,task:swingup,pixels:32,depth:true,segmentation:true")


def test_observation_has_images_and_state(arena):
    spec = arena.observation_spec
    assert spec["pixels"] == image_spec(32, 32) == Box(0, 255, (32, 32, 3), jnp.uint8)
    assert spec["depth"].shape == (32, 32) and spec["segmentation"].shape == (32, 32, 2)
    assert set(spec.spaces) == {"pixels", "depth", "segmentation", "position", "velocity"}
    state_only = jarena.build_arena("dmc|domain:cartpole,task:swingup")
    params = arena.default_params()
    reset, step = jax.jit(jarena.batch_reset, static_argnums=(0, 2)), jax.jit(arena.step)
    states, info = reset(arena, jax.random.key(0), 3, params)
    one = jax.tree_util.tree_map(lambda x: x[1], states)
    state, info_step = step(one, jnp.array([0.7]))
    # the images are the camera's render of the state after the step, the state keys the suite's
    scene = camera.scene_of(model_of(arena.dynamics))
    frame = jax.jit(camera.render, static_argnums=(0, 2, 3, 4))(scene, state.physics, 0, 32, 32)
    np.testing.assert_array_equal(info_step.observation["pixels"], frame.rgb)
    np.testing.assert_array_equal(info_step.observation["segmentation"], frame.segmentation)
    np.testing.assert_allclose(info_step.observation["depth"], frame.depth, rtol=1e-6)
    state_info = jax.jit(state_only.step)(one, jnp.array([0.7]))[1]
    np.testing.assert_allclose(info_step.observation["position"], state_info.observation["position"], rtol=1e-6)
    assert bool(spec.contains(info_step.observation))
    # the three arenas start apart: their pictures differ
    assert not np.array_equal(info.observation["pixels"][0], info.observation["pixels"][1])
    # the same episode gives the same picture in any batch
    single, single_info = jax.jit(arena.reset)(None, params, states.episode[1])
    np.testing.assert_array_equal(single_info.observation["pixels"], info.observation["pixels"][1])


def test_images_only_and_other_cameras():
    arena = jarena.build_arena("dmc|domain:cartpole,task:balance,pixels:[24,40],state:false,camera:lookatcart")
    assert set(arena.observation_spec.spaces) == {"pixels"}
    assert arena.observation_spec["pixels"].shape == (24, 40, 3)
    assert "lookatcart" in arena.sensor.name
    assert arena.name == "dmc-cartpole-balance-pixels24x40"  # its own benchmark: runs and configs apart
    assert jarena.build_arena("dmc|domain:cartpole,pixels:64").name == "dmc-cartpole-balance-pixels64"


@pytest.mark.parametrize("text, message", [
    ("dmc|domain:cartpole,depth:true", "depth need pixels"),
    ("dmc|domain:cartpole,state:false", "state need pixels"),
    ("dmc|domain:cartpole,pixels:0", r"pixels must be a side or \[height, width\]"),
    ("dmc|domain:cartpole,pixels:[1,2,3]", r"pixels must be a side or \[height, width\]"),
    ("dmc|domain:cartpole,pixels:64,camera:top", r"no camera named 'top'; its cameras: 0: fixed, 1: lookatcart"),
    ("dmc|domain:cartpole,pixels:64,camera:7", "camera must be a model camera's name or id"),
    ("dmc|domain:cartpole,pixels:64,depth:3", "depth must be true or false"),
])
def test_bad_options_are_clear_errors(text, message):
    with pytest.raises(ArenaStringError, match=message):
        jarena.build_arena(text)
