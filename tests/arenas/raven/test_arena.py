"""The Raven block-insertion arena: episodes, the heightmap, the suction primitive, faults and the oracle.

The arena's step takes some 19 s of CPU to compile (MJX's physics), so every test here shares one arena's jitted
batched reset, step and oracle for a batch of three, and one program that starts, acts on and steps one arena alone
(unbatched) for the batch-size check; reset and step are traced once, for one arena, and batched by ``vmap``. All
are compiled with XLA's quick options (the step in 7.5 s): the behaviour checked does not depend on them.
"""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.raven import heightmap, physics, poses, scoring
from jarena.building.grammar import ArenaStringError
from jarena.core import faults
from tests.arenas.raven import FAST_COMPILE

ARENA = "raven|task:block-insertion"
EPISODES = np.arange(3)  # eval episodes 0, 1, 2


@pytest.fixture(scope="module")
def raven():
    """The arena, its oracle, the jitted batched programs and the one-arena program, with eval episodes 0-2 reset."""
    arena = jarena.build_arena(ARENA)
    oracle = jarena_agents.build_agent("oracle_raven")
    reset_one, step_one = jax.jit(lambda e: arena.reset(None, episode=e)), jax.jit(arena.step)  # traced once

    def act(info, key, state):
        return oracle.act(oracle.init(key, arena.spec, 1), info, key, state)[0]

    def alone(episode, key):
        """One arena, unbatched: its start, the oracle's action and the step, in one program."""
        state, info = reset_one(episode)
        action = act(info, key, state)
        after, outcome = step_one(state, action)
        return info, action, after, outcome

    reset, step = (jax.jit(jax.vmap(f), compiler_options=FAST_COMPILE) for f in (reset_one, step_one))
    states, infos = reset(EPISODES)
    return SimpleNamespace(arena=arena, reset=reset, step=step, act=jax.jit(act, compiler_options=FAST_COMPILE),
                           alone=jax.jit(alone, compiler_options=FAST_COMPILE), states=states, infos=infos)


_poses = jax.jit(jax.vmap(scoring.planar_poses))  # (B, 2, 4): the block's and the fixture's (x, y, z, yaw)
_pixels = jax.jit(heightmap.world_to_pixel)
# (B,): the z component of each arena's block's up axis
_block_up = jax.jit(jax.vmap(lambda p: poses.rotate(physics.object_poses(p)[1][0], jnp.asarray([0.0, 0.0, 1.0]))[2]))


def _host(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def _assert_same(a, b, what):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=what)


def test_the_arena_string_builds_and_names_bad_keys():
    arena = jarena.build_arena(ARENA)
    assert ARENA in jarena.list_arenas("raven") and ARENA in jarena.list_arenas("benchmark")
    assert arena.observation_spec["rgb"].shape == (320, 160, 3)
    assert arena.observation_spec["height"].shape == (320, 160)
    assert arena.action_spec.shape == (5,) and arena.max_episode_steps == 3  # Ravens' max_steps
    with pytest.raises(ArenaStringError, match="block-insertion"):
        jarena.build_arena("raven|task:stack-everything")
    with pytest.raises(ArenaStringError, match="settle must be a positive integer"):
        jarena.build_arena("raven|settle:0")


def test_episodes_are_fixed_and_laid_out_apart_in_the_workspace(raven):
    arena, states, infos = raven.arena, raven.states, raven.infos
    again = raven.reset(EPISODES)
    _assert_same(infos, again[1], "an episode id gives the same start every time")
    assert list(arena.episodes("eval")) == list(range(100)) and arena.episodes("val")[0] == 1 << 20
    planar = np.asarray(_poses(states.physics))
    block, fixture = planar[:, 0], planar[:, 1]
    for xy in (block[:, :2], fixture[:, :2]):  # 23 pixels (7.3 cm) from the edges, as Ravens' eroded free space
        assert np.all(xy[:, 0] > 0.25 + 0.07) and np.all(xy[:, 0] < 0.75 - 0.07)
        assert np.all(np.abs(xy[:, 1]) < 0.5 - 0.07)
    # the fixture's 45-pixel square around its origin is clear of the block
    rc_block, rc_fixture = np.asarray(_pixels(np.stack([block[:, :2], fixture[:, :2]])))
    assert np.all(np.max(np.abs(rc_block - rc_fixture), axis=-1) > 22)
    np.testing.assert_allclose(planar[:, :, 2], 0.02, atol=1e-6)  # on the table
    np.testing.assert_allclose(infos.goal, fixture, atol=1e-6)  # the goal: the fixture's pose
    assert len(set(np.round(block[:, 0], 4))) == 3  # three different layouts
    # the heightmap: the block's corner (its origin) 4 cm high in its red, the table 0 in dark grey
    rc = np.round(rc_block).astype(int)
    observation = _host(infos.observation)
    for i, (r, c) in enumerate(rc):
        assert float(observation["height"][i, r, c]) == pytest.approx(0.04, abs=1e-6)
        assert observation["rgb"][i, r, c].tolist() == [255, 87, 89]
        assert float(observation["height"][i, 2, 2]) == 0.0 and observation["rgb"][i, 2, 2].tolist() == [51, 51, 51]
    assert bool(np.all(jax.jit(jax.vmap(arena.observation_spec.contains))(infos.observation)))


def test_the_oracle_inserts_the_block_the_same_in_any_batch(raven):
    """Eval episodes 0-2 succeed in one action, the block within a millimetre of the fixture's pose, the weld
    holding it to the cup while lifted. Episode 1 alone (one arena, unbatched) starts and is acted on to the same
    bits, and steps to the same outcome: MJX's solver rounds differently in batches of different sizes (some 1e-7 m
    per physics step)."""
    actions = raven.act(raven.infos, jax.random.key(0), raven.states)
    after, info = raven.step(raven.states, actions)
    assert info.success.tolist() == [True] * 3 and info.terminated.tolist() == [True] * 3
    np.testing.assert_allclose(info.reward, 1.0)
    metrics = _host(info.metrics)
    assert float(np.max(metrics["position_error"])) < 1e-3
    assert float(np.max(metrics["rotation_error"])) < np.deg2rad(1.0)
    # while lifted for a control step the block sags under a quarter of the free fall of that time
    fall = 0.5 * 9.81 * raven.arena.dynamics.timestep ** 2
    assert 0 < float(np.max(metrics["grasp_slip"])) < min(0.25 * fall, 1e-3)

    one_info, one_action, one_after, one_step = raven.alone(EPISODES[1], jax.random.key(0))
    _assert_same((one_info, one_action), jax.tree_util.tree_map(lambda x: np.asarray(x)[1], (raven.infos, actions)),
                 "episode 1 alone and in a batch of three")
    assert one_step.success.shape == () and bool(one_step.success) and float(one_step.reward) == float(info.reward[1])
    np.testing.assert_allclose(one_after.physics.data.qpos, np.asarray(after.physics.data.qpos)[1], atol=1e-5)
    np.testing.assert_allclose(one_step.observation["height"], np.asarray(info.observation["height"])[1], atol=1e-5)


def _free_point(planar: np.ndarray) -> np.ndarray:
    """A point of the workspace far from both objects (x, y)."""
    grid = np.stack(np.meshgrid(np.linspace(0.35, 0.65, 7), np.linspace(-0.4, 0.4, 17)), -1).reshape(-1, 2)
    distance = np.min(np.linalg.norm(grid[:, None] - planar[None, :, :2], axis=-1), axis=-1)
    return grid[np.argmax(distance)]


def test_suction_carries_a_block_where_the_primitive_puts_it_and_hand_placed_blocks_score(raven):
    """Arena 0: the cup picks the block at its corner and puts it at a free point turned by 0.5 rad; it comes to
    rest there, upright, within a millimetre. Arenas 1 and 2: the block is set in the fixture 0.9 cm and 1.1 cm off
    (within the channel's 9 mm play on each axis) and a step that grasps nothing scores it: a match and no
    match. Then bad actions: a NaN faults and runs the no-op, a pick off the heightmap is clipped."""
    states = raven.states
    planar = np.asarray(_poses(states.physics))
    place_xy = _free_point(planar[0])
    pick, place = np.asarray(_pixels(np.stack([planar[0, 0, :2], place_xy])))
    action = np.concatenate([pick, place, [0.5]]).astype(np.float32)

    # blocks 1 and 2 set in their fixture, off along the fixture's diagonal
    qpos = np.asarray(states.physics.data.qpos).copy()
    for i, distance in ((1, 0.009), (2, 0.011)):
        x, y, z, yaw = planar[i, 1]
        offset = distance / np.sqrt(2) * np.asarray([np.cos(yaw) - np.sin(yaw), np.sin(yaw) + np.cos(yaw)])
        qpos[i, :7] = [x + offset[0], y + offset[1], z, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
    states = states.replace(physics=states.physics.replace(data=states.physics.data.replace(qpos=jnp.asarray(qpos))))
    no_op = np.asarray(raven.arena.no_op())
    after, info = raven.step(states, jnp.asarray(np.stack([action, no_op, no_op])))
    moved = np.asarray(_poses(after.physics))
    np.testing.assert_allclose(moved[0, 0, :2], place_xy, atol=1e-3)
    turn = moved[0, 0, 3] - planar[0, 0, 3] - 0.5  # wrapped to [-pi, pi)
    assert float(np.mod(turn + np.pi, 2 * np.pi) - np.pi) == pytest.approx(0.0, abs=np.deg2rad(0.5))
    assert moved[0, 0, 2] == pytest.approx(0.02, abs=5e-4)
    assert float(np.asarray(_block_up(after.physics))[0]) > np.cos(np.deg2rad(1.0))
    assert not np.asarray(after.physics.held)[0] >= 0  # released
    assert float(np.asarray(info.metrics["grasp_slip"])[0]) < 1e-3
    np.testing.assert_allclose(moved[1:, 0, :2], qpos[1:, :2], atol=5e-4)  # the set blocks stay put
    assert info.metrics["placed"].tolist() == [0.0, 1.0, 0.0] and info.success.tolist() == [False, True, False]
    np.testing.assert_allclose(info.reward, [0.0, 1.0, 0.0])

    bad = np.stack([np.full(5, np.nan, np.float32), np.asarray([-40.0, 400.0, 500.0, -3.0, 9.0], np.float32),
                    action])
    after_bad, info_bad = raven.step(raven.states, jnp.asarray(bad))
    fault, terminated = np.asarray(info_bad.fault), np.asarray(info_bad.terminated)
    assert faults.describe(fault[0]) == ["invalid action"] and bool(terminated[0])
    assert float(np.asarray(info_bad.reward)[0]) == 0.0
    assert int(fault[1]) == 0 and int(fault[2]) == 0
    np.testing.assert_allclose(np.asarray(_poses(after_bad.physics))[:2, 0], planar[:2, 0], atol=1e-4)
    assert bool(np.all(np.isfinite(np.asarray(after_bad.physics.data.qpos))))
