"""Frames of selected arenas of a batch: MuJoCo (dmc cartpole) and classic arenas, grids, errors."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.render import (
    RenderError,
    VideoOptions,
    can_render,
    check_video,
    render_batch,
    render_trajectory,
    renderer,
    tile,
)


def stack(trees):
    return jax.tree_util.tree_map(lambda *x: np.stack(x), *jax.device_get(trees))


@pytest.fixture(scope="module")
def dmc():
    return jarena.build_arena("dmc|domain:cartpole,task:swingup")


def dmc_physics(arena, cart, pole):
    """An ``mjx.Data`` with the cart at ``cart`` m and the pole at ``pole`` rad (no compilation needed)."""
    data = jax.device_get(arena.dynamics.init(jax.random.key(0), arena.default_params().dynamics))
    return data.replace(qpos=np.array([cart, pole], np.float32))


def changed(a, b):
    """Fraction of pixels that differ between two frames."""
    return float(np.mean(np.any(a != b, axis=-1)))


def test_dmc_cartpole_frames_show_the_pole_moving(dmc):
    batch = stack([dmc_physics(dmc, 0.0, 0.0), dmc_physics(dmc, 0.0, 1.0), dmc_physics(dmc, 0.5, 2.5)])
    frames = render_batch(dmc, batch, width=96, height=72)
    assert frames.shape == (3, 72, 96, 3) and frames.dtype == np.uint8
    assert all(f.std() > 10 for f in frames)  # a lit scene, not a blank image
    assert changed(frames[0], frames[1]) > 0.005 and changed(frames[1], frames[2]) > 0.01
    np.testing.assert_array_equal(render_batch(dmc, batch, [2], width=96, height=72)[0], frames[2])
    cart_view = render_batch(dmc, batch, [0], width=96, height=72, camera="lookatcart")[0]
    assert cart_view.std() > 10 and changed(cart_view, frames[0]) > 0.2
    # a trajectory (T = 2, B = 2) of two arenas, tiled side by side
    trajectory = stack([stack([dmc_physics(dmc, 0.0, 0.0), dmc_physics(dmc, 0.5, 2.5)]),
                        stack([dmc_physics(dmc, 0.0, 1.0), dmc_physics(dmc, 0.0, 0.0)])])
    video = render_trajectory(dmc, trajectory, [0, 1], width=96, height=72)
    assert video.shape == (2, 72, 2 * 96 + 2, 3)
    np.testing.assert_array_equal(video[:, :, :96], frames[[0, 1]])
    np.testing.assert_array_equal(video[:, :, 98:], frames[[2, 0]])
    check_video(dmc, VideoOptions(camera="lookatcart"))
    with pytest.raises(RenderError, match=r"cannot render a 320 x 240 frame from camera 'top': .*does not exist"):
        check_video(dmc, VideoOptions(camera="top"))  # what record_video, run and evaluate check before compiling


def test_render_batch_selects_arenas_and_their_params():
    arena = jarena.build_arena("classic|domain:cartpole")
    state, _ = jarena.batch_reset(arena, jax.random.key(0), 5)
    state = state.replace(physics=state.physics.replace(x=jnp.linspace(-2.0, 2.0, 5)))
    frames = render_batch(arena, state, [3, 0], width=120, height=80)
    for frame, i in zip(frames, [3, 0], strict=True):
        one = jax.tree_util.tree_map(lambda x, i=i: x[i], state.physics)
        np.testing.assert_array_equal(frame, arena.dynamics.render(one, arena.default_params().dynamics,
                                                                   width=120, height=80))
    assert changed(frames[0], frames[1]) > 0.01
    np.testing.assert_array_equal(render_batch(arena, state.physics, 3, width=120, height=80)[0], frames[0])
    # per-arena params (params_axis=0): each arena is drawn with its own pole length
    params = jax.vmap(lambda length: arena.default_params().replace(
        dynamics=arena.default_params().dynamics.replace(length=length)))(jnp.array([0.25, 0.5, 1.0, 0.5, 0.5]))
    poles = render_batch(arena, state, [0, 2], params=params, params_axis=0, width=240, height=160)
    pole_pixels = [np.all(f == np.array([202, 152, 101], np.uint8), axis=-1).sum() for f in poles]
    assert pole_pixels[1] > 3 * pole_pixels[0]
    with pytest.raises(RenderError, match=r"indices \[5\] are out of range for a batch of 5"):
        render_batch(arena, state, [1, 5])


def test_render_trajectory_stride_and_tile():
    arena = jarena.build_arena("classic|domain:pendulum")
    states, _ = jarena.batch_reset(arena, jax.random.key(0), 3)
    trajectory = stack([states.replace(physics=states.physics.replace(theta=states.physics.theta + 0.3 * t))
                        for t in range(5)])  # (T = 5, B = 3)
    single = render_trajectory(arena, trajectory, 1, width=64, height=48)
    assert single.shape == (5, 48, 64, 3)
    assert all(changed(a, b) > 0.005 for a, b in zip(single[:-1], single[1:], strict=True))
    np.testing.assert_array_equal(render_trajectory(arena, trajectory, 1, width=64, height=48, stride=2),
                                  single[::2])
    grid = render_trajectory(arena, trajectory, [0, 1, 2], width=64, height=48, columns=2)
    assert grid.shape == (5, 2 * 48 + 2, 2 * 64 + 2, 3)
    np.testing.assert_array_equal(grid[:, :48, 66:], single)  # first row, second column: arena 1
    assert not grid[:, 50:, 66:].any()  # the empty cell (second row, second column) is black
    assert tile(np.stack([single] * 3), columns=3).shape == (5, 48, 3 * 64 + 4, 3)
    with pytest.raises(RenderError, match="stride must be a positive integer"):
        render_trajectory(arena, trajectory, 0, stride=0)


def test_an_arena_without_renderer_is_a_clear_error():
    arena = jarena.build_arena("classic|domain:cartpole")
    blind = dataclasses.replace(arena, dynamics=dataclasses.replace(arena.dynamics, render=None), name="blind-arena",
                                build_string=None)
    assert can_render(arena) and not can_render(blind)
    with pytest.raises(RenderError) as error:
        renderer(blind)
    message = str(error.value)
    assert "arena 'blind-arena' cannot render" in message and "no render function" in message
    assert "classic|domain:cartpole" in message and "classic|domain:point_mass" in message
    assert "dmc|domain:cartpole" in message
    state, _ = jarena.batch_reset(blind, jax.random.key(0), 2)
    with pytest.raises(RenderError, match="blind-arena"):
        render_batch(blind, state)
