"""Cloth arenas from strings: pieces, errors, the pick-and-place primitive, initial states and the oracle."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas.cloth import camera, coverage
from jarena.arenas.cloth.tools import WORKSPACE_HALF_WIDTH
from jarena.building.grammar import ArenaStringError
from tests.arenas.cloth.episodes import Episodes

SMALL = "particles:16,resolution:32,horizon:4"


def _arena(extra: str = "", **keys) -> jarena.Arena:
    pairs = ",".join(f"{k}:{v}" for k, v in keys.items())
    return jarena.build_arena(f"cloth|{SMALL}" + (f",{pairs}" if pairs else "") + extra)


def _batch_reset(arena: jarena.Arena):
    """``episodes -> (states, infos)``: the arena's reset of a batch of episode ids as one compiled program (run op
    by op, one reset dispatches hundreds of small programs)."""
    return jax.jit(jax.vmap(lambda e: arena.reset(episode=e)))


_row = jax.jit(lambda tree, i: jax.tree_util.tree_map(lambda x: x[i], tree))  # one episode of a batch
SIX = jnp.arange(6)


@pytest.fixture(scope="module")
def flat():
    """The flat SMALL arena, its batched reset and its first six episodes' starts (states, infos), reset once for
    the module."""
    arena = _arena(initial="flat")
    reset = _batch_reset(arena)
    return SimpleNamespace(arena=arena, reset=reset, six=reset(SIX))


@pytest.fixture(scope="module")
def crumpled():
    """The crumpled SMALL arena's first six episodes, reset once for the module as the evaluation resets them (the
    same program as the flattening oracle's episodes below: the horizon takes no part in the reset)."""
    return Episodes(_arena(initial="crumpled"), SIX)


def test_the_benchmark_strings_are_listed_and_build():
    listed = jarena.list_arenas("cloth")
    assert "cloth|domain:square_fabric,initial:crumpled,action:pixel_pick_and_place(1),task:flattening" in listed
    benchmark = set(jarena.list_arenas("benchmark"))
    assert all(s in benchmark for s in listed if "initial:crumpled" in s and "task:flattening" in s)
    folds = [s for s in listed if "task:flattening" not in s]
    assert len(folds) == 12 and all((s in benchmark) == ("initial:flat," in s) for s in folds)
    arena = jarena.build_arena(next(s for s in listed if "task:flattening" in s))
    assert arena.observation_spec["rgb"].shape == (128, 128, 3)
    assert arena.observation_spec["depth"].shape == (128, 128)
    assert arena.action_spec.shape == (4,)
    assert arena.max_episode_steps == 30
    assert arena.dynamics.name == "cloth"


@pytest.mark.parametrize("string, words", [
    ("cloth|domain:towel", ["square_fabric", "rectangular_fabric"]),
    ("cloth|task:folding_in_half", ["flattening"]),
    ("cloth|initial:wet", ["crumpled", "flat"]),
    ("cloth|action:pick_and_place(0)", ["positive number of pickers"]),
    ("cloth|particles:2", ["particles", ">= 3"]),
    ("cloth|size:[0.4,2.0]", ["size"]),
    ("cloth|horizon:0", ["horizon"]),
    ("cloth|depth:no", ["depth", "true or false"]),
])
def test_bad_strings_name_the_valid_choices(string, words):
    with pytest.raises(ArenaStringError) as e:
        jarena.build_arena(string)
    for word in words:
        assert word in str(e.value)


def test_the_pickers_follow_the_tool():
    assert _arena(action="pick_and_place(2)").dynamics.control_spec.shape == (2, 4)
    assert _arena(action="pick_and_place(2)").action_spec.shape == (8,)
    low_level = _arena(action="picker(0.05)")
    assert low_level.action_spec.shape == (1, 4)


def test_a_pick_and_place_leaves_the_grasped_particle_at_the_place_point():
    arena = _arena(initial="flat", action="pick_and_place(1)")
    # (the tool takes no part in the reset: the same program as the flat fixture's, loaded from the compilation cache)
    state = _row(_batch_reset(arena)(SIX)[0], 3)
    x = np.asarray(state.physics.positions)
    pick_particle = int(np.argmin(np.linalg.norm(x[:, :2], axis=-1)))  # the cloth's middle
    pick = x[pick_particle, :2]
    place = pick + np.array([0.08, -0.05])
    action = jnp.asarray(np.concatenate([pick, place]) / WORKSPACE_HALF_WIDTH, jnp.float32)
    state, info = jax.jit(arena.step)(state, action)
    after = np.asarray(state.physics.positions)
    assert np.linalg.norm(after[pick_particle, :2] - place) < 0.01
    assert info.fault == 0
    assert not bool(state.physics.grasped.any())  # released
    np.testing.assert_allclose(np.asarray(state.physics.picker_positions), [[0, 0, 0.3]], atol=1e-5)  # ready pose


def test_pixel_pick_and_place_picks_where_the_camera_sees_the_point(flat):
    arena = flat.arena
    # reset op by op, as this check was calibrated: the four particles nearest the middle of a flat grid tie, and a
    # compiled reset's last bits pick another, which lands 1.06 cm from the place point
    state, _ = arena.reset(episode=5)
    x = np.asarray(state.physics.positions)
    middle = int(np.argmin(np.linalg.norm(x[:, :2] - x[:, :2].mean(0), axis=-1)))
    uv = np.asarray(camera.world_to_pixel(jnp.asarray(x[middle]), camera.CameraParams()))
    place_uv = uv + np.array([0.1, 0.05])  # right and down in the image: +x and -y in the world
    state, info = jax.jit(arena.step)(state, jnp.asarray(np.concatenate([uv, place_uv]), jnp.float32))
    place = np.asarray(camera.pixel_to_world(jnp.asarray(place_uv), 0.02, camera.CameraParams()))
    assert place[0] > x[middle, 0] + 0.05 and place[1] < x[middle, 1] - 0.02
    assert np.linalg.norm(np.asarray(state.physics.positions[middle, :2]) - place) < 0.01


def test_flat_starts_are_flat_and_crumpled_starts_are_not(flat, crumpled):
    _, flat_info = flat.six
    states, crumpled_info = crumpled.start
    assert np.all(np.asarray(flat_info.metrics["normalised_coverage"]) > 0.99)
    crumpled_coverage = np.asarray(crumpled_info.metrics["normalised_coverage"])
    assert crumpled_coverage.mean() < 0.85 and len(set(np.round(crumpled_coverage, 3))) == 6
    # the metric is the coverage module's, from the particles (compiled: op by op it is a hundred small programs)
    mesh = states.physics.mesh
    covered = jax.jit(jax.vmap(lambda x: coverage.normalised_coverage(x, mesh)))(states.physics.positions)
    np.testing.assert_allclose(np.asarray(crumpled_info.metrics["normalised_coverage"]), np.asarray(covered),
                               rtol=1e-6)


def test_episodes_are_deterministic_and_flat_starts_the_same_in_any_batch(flat, crumpled):
    first, second = crumpled.start[0], crumpled.reset(SIX, crumpled.params)[0]  # the fixture's reset, run again
    np.testing.assert_array_equal(np.asarray(first.physics.positions), np.asarray(second.physics.positions))
    one = flat.reset(jnp.array([4]))[0].physics.positions[0]
    many = flat.six[0].physics.positions[4]
    np.testing.assert_array_equal(np.asarray(one), np.asarray(many))


def test_a_jit_holding_the_params_as_constants_steps_the_same_cloth_as_one_taking_them_as_arguments():
    # XLA folds constant params at compile time, a last-bit difference that a crumpled cloth grows to millimetres
    # in a few actions (measured without the barriers: 30 um after one action, 1.5 mm after three)
    arena = jarena.build_arena("cloth|particles:10,resolution:16,horizon:4")
    params = arena.default_params()
    actions = jnp.array([[0.1, 0.2, -0.3, -0.1], [-0.2, -0.1, 0.3, 0.2]], jnp.float32)

    def episode(params):
        state, info = arena.reset(jax.random.key(3), params)
        return jax.lax.scan(lambda s, a: arena.step(s, a, params), state, actions)[1]

    baked, passed = jax.jit(lambda: episode(params))(), jax.jit(episode)(params)
    leaves = zip(jax.tree_util.tree_leaves(baked), jax.tree_util.tree_leaves(passed), strict=True)
    for leaf_baked, leaf_passed in leaves:
        np.testing.assert_array_equal(np.asarray(leaf_baked), np.asarray(leaf_passed))
    assert np.abs(np.diff(np.asarray(baked.metrics["normalised_coverage"]))).max() > 0  # the actions moved it


def test_the_observation_is_the_top_down_camera(flat):
    state, info = flat.six
    mesh = state.physics.mesh
    # each of the six starts rendered alone, compiled as the reset is (its rendering is batched the same way)
    image = jax.jit(jax.vmap(lambda x: camera.render(x, mesh, camera.CameraParams(), 32)))(state.physics.positions)
    np.testing.assert_array_equal(np.asarray(info.observation["rgb"]), np.asarray(image["rgb"]))
    np.testing.assert_array_equal(np.asarray(info.observation["mask"]), np.asarray(image["mask"]).astype(np.uint8))
    seen = np.asarray(info.observation["mask"]).sum((1, 2))
    assert (seen > 0).all() and (seen < 32 * 32).all(), seen


def test_depth_and_mask_can_be_left_out(flat):
    rgb_only = jarena.build_arena(f"cloth|initial:flat,{SMALL},depth:false,mask:false")
    assert set(rgb_only.observation_spec.spaces) == {"rgb"}
    _, info = _batch_reset(rgb_only)(SIX)
    full = flat.six[1]
    np.testing.assert_array_equal(np.asarray(info.observation["rgb"]), np.asarray(full.observation["rgb"]))
    assert set(jarena.build_arena(f"cloth|{SMALL},mask:false").observation_spec.spaces) == {"rgb", "depth"}


def test_the_flattening_oracle_raises_coverage():
    from jarena_agents.registry import build_agent

    arena = jarena.build_arena("cloth|domain:square_fabric,initial:crumpled,particles:16,resolution:32,horizon:6")
    # evaluate's loop on episodes 0-5 for both agents, with one compiled reset and step (the reset loaded from the
    # compilation cache: the crumpled fixture's program)
    episodes = Episodes(arena, SIX)
    before = np.asarray(episodes.start[1].metrics["normalised_coverage"])
    after = np.asarray(episodes.run(build_agent("oracle_cloth_flattening", {"lookahead": False})).metrics[
        "normalised_coverage"])
    assert after.mean() > before.mean() + 0.08, (before, after)
    assert np.mean(after >= 0.9) >= 0.6, after
    random = episodes.run(build_agent("random"))
    assert after.mean() > np.asarray(random.metrics["normalised_coverage"]).mean() + 0.15
