"""The PushT arenas: the contract every arena passes, observations, the coverage task, strings and videos.

One image arena serves every test: its contract checks compile its reset and step once, and the other tests run
those same programs (``jarena.testing``'s shared ones). Its images are 32 x 32 and its episodes 20 actions long:
neither the drawing nor the dynamics depends on them, and they shorten the contract's rollouts.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas import pusht
from jarena.arenas.pusht import geometry, physics, render
from jarena.building.grammar import ArenaStringError
from jarena.testing import check_arena
from jarena.testing.contract import _programs

ARENA = "pusht|obs:image,resolution:32,time_limit:20"


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena(ARENA)


def test_image_arena_passes_every_contract_check(arena):
    check_arena(arena)


def _step_from(arena, pusher, pose, target):
    """The info of one action from a scene placed at rest, through the arena's shared jitted programs."""
    programs = _programs(arena)
    params = arena.default_params()
    state, _ = programs.reset(jax.random.key(3), params)
    state = state.replace(physics=physics.place(jnp.float32(pusher), jnp.float32(pose), params.dynamics))
    return programs.step(state, jnp.float32(target), params)


def test_covering_the_goal_succeeds_and_ends_the_episode(arena):
    _, info = _step_from(arena, (60.0, 60.0), geometry.GOAL_POSE, (60.0, 60.0))
    assert bool(info.success) and bool(info.terminated) and not bool(info.truncated)
    assert float(info.reward) == 1.0
    for name in ("coverage", "max_coverage"):
        assert float(info.metrics[name]) > 1 - 1e-5
    assert float(info.metrics["max_reward"]) == 1.0
    np.testing.assert_allclose(info.goal, geometry.GOAL_POSE, atol=1e-6)


def test_reward_scales_coverage_and_the_episode_goes_on(arena):
    pose = (256.0, 276.0, math.pi / 4)  # shifted along y: about half the goal covered
    state, info = _step_from(arena, (60.0, 60.0), pose, (60.0, 60.0))
    covered = 0.5247440  # shapely's area(T ∩ goal) / area(goal) for this pose
    np.testing.assert_allclose(float(info.metrics["coverage"]), covered, atol=1e-6)
    np.testing.assert_allclose(float(info.reward), covered / 0.95, atol=1e-6)
    assert not bool(info.success) and not bool(info.terminated)
    # the running maxima keep the best step of the episode (Diffusion Policy's score) after it is undone
    state = state.replace(physics=state.physics.replace(block=jnp.float32([400.0, 400.0])))
    _, info = _programs(arena).step(state, jnp.float32([60.0, 60.0]), arena.default_params())
    assert float(info.metrics["coverage"]) < 1e-6 and float(info.reward) < 1e-6
    np.testing.assert_allclose(float(info.metrics["max_coverage"]), covered, atol=1e-6)
    np.testing.assert_allclose(float(info.metrics["max_reward"]), covered / 0.95, atol=1e-6)


def _pixel(image, point):
    """The pixel of ``image`` (R, R, 3) over plane point ``(x, y)``: column x, row y."""
    r = image.shape[0]
    return tuple(int(v) for v in image[int(point[1] * r / 512), int(point[0] * r / 512)])


def test_image_shows_pusher_block_and_goal(arena):
    pose = (380.0, 100.0, 0.0)
    pusher = (104.0, 408.0)  # a pixel's centre: its 2 x 2 samples, 4 units off, fall in the disc's core
    _, info = _step_from(arena, pusher, pose, pusher)
    image, agent = np.asarray(info.observation["image"]), np.asarray(info.observation["agent_pos"])
    assert image.shape == (32, 32, 3) and image.dtype == np.uint8
    np.testing.assert_allclose(agent, pusher, atol=1e-3)
    assert _pixel(image, pusher) == render.PUSHER_CORE
    assert _pixel(image, (380.0, 145.0)) == render.BLOCK  # the block's centre of gravity
    goal_centre = np.asarray(geometry.to_plane(jnp.float32(geometry.GOAL_POSE), jnp.float32([[0.0, 45.0]])))[0]
    assert _pixel(image, goal_centre) == render.GOAL
    assert _pixel(image, (300.0, 460.0)) == render.WHITE
    # the same scene at the reference canvas' 512 x 512, a point per pixel: each colour of the palette appears
    big = np.asarray(jax.jit(render.render, static_argnames=("size", "samples"))(
        jnp.float32(pusher), jnp.float32(pose), size=512, samples=1))
    colours = {tuple(c) for c in big.reshape(-1, 3)}
    for colour in (render.WHITE, render.GOAL, render.BLOCK, render.OUTLINE, render.PUSHER, render.PUSHER_CORE,
                   render.WALL):
        assert colour in colours, colour


def test_state_and_keypoint_observations():
    """Values and specs, also for a block squeezed into a wall and an angle past a turn."""
    params = physics.PushTParams()
    scenes = [((10.0, 500.0), (300.0, 200.0, -0.5)), ((512.0, 0.0), (520.0, 100.0, 7.0)),
              ((256.0, 256.0), (-20.0, 600.0, -3.0))]
    states = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[
        physics.place(jnp.float32(p), jnp.float32(q), params) for p, q in scenes])
    for obs in ("state", "keypoints"):
        sensor = pusht.sensor(obs)
        seen = jax.jit(jax.vmap(lambda s, sensor=sensor: sensor.observe(s, ())))(states)
        assert bool(jnp.all(jax.vmap(sensor.spec.contains)(seen))), obs
        for i, (pusher, pose) in enumerate(scenes):
            if obs == "state":
                want = [*pusher, pose[0], pose[1], pose[2] % (2 * math.pi)]
                np.testing.assert_allclose(seen["state"][i], want, atol=1e-4)
            else:
                np.testing.assert_allclose(seen["agent_pos"][i], pusher, atol=1e-6)
                c, s = math.cos(pose[2]), math.sin(pose[2])
                want = geometry.KEYPOINTS @ np.array([[c, -s], [s, c]]).T + pose[:2]
                np.testing.assert_allclose(seen["keypoints"][i], want, atol=1e-3)


def test_strings_errors_and_registry():
    assert {"pusht|obs:image", "pusht|obs:state", "pusht|obs:keypoints"} <= set(jarena.list_arenas("pusht"))
    built = jarena.build_arena("pusht|obs:state")
    assert built.max_episode_steps == 300 and built.name == "pusht-state"
    assert built.dynamics.timestep == pytest.approx(0.1)  # 10 physics steps of 10 ms: 10 Hz control
    with pytest.raises(ArenaStringError, match="image.*state.*keypoints"):
        jarena.build_arena("pusht|obs:pixels")
    with pytest.raises(ArenaStringError, match="substeps"):
        jarena.build_arena("pusht|substeps:0")


def test_frames_for_videos(arena):
    state, _ = _programs(arena).reset(jax.random.key(0), arena.default_params())
    frame = arena.dynamics.render(jax.device_get(state.physics), width=320, height=240)
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    assert np.all(frame[:, :40] == 255) and len(np.unique(frame.reshape(-1, 3), axis=0)) > 5  # letterboxed scene
