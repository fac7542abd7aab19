"""``oracle_pusht``: hand-worked targets, the same actions for any key and batch, and eval episodes won (all 100
eval episodes in ``docs/arenas/pusht.md``)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas import pusht
from jarena_agents.oracles.pusht import PushTOracleConfig, target
from jarena_agents.registry import build_agent

STATE = "pusht|obs:state"
GOAL = np.array(pusht.GOAL_POSE, np.float32)


def _plane(pose, body_point):
    """A body-frame point of a block at ``pose`` in the plane (numpy)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([c * body_point[0] - s * body_point[1], s * body_point[0] + c * body_point[1]]) + pose[:2]


@pytest.fixture(scope="module")
def targets():
    """The default oracle's target for a batch of (pusher, pose) pairs, the goal the task's, as one program."""
    cfg = PushTOracleConfig()
    return jax.jit(jax.vmap(lambda p, q: target(p, q, jnp.asarray(GOAL), cfg)))


def test_a_block_short_of_the_goal_along_its_stem_is_pushed_through_its_centre_of_gravity(targets):
    # the block 20 units back along its own -y: the push through the centre of gravity, from the middle of the
    # bar's outer edge, moves it straight there (twist (0, 1, 0) per unit: push 20); with the disc on that
    # contact's normal the target is 1.5 x 20 units into the face, 15 - 30 = -15 units past the edge
    pose = np.array([*_plane(GOAL, (0.0, -20.0)), GOAL[2]], np.float32)
    pusher = _plane(pose, (0.0, -16.0)).astype(np.float32)
    got = np.asarray(targets(jnp.asarray(pusher[None]), jnp.asarray(pose[None])))[0]
    np.testing.assert_allclose(got, _plane(pose, (0.0, 15.0)), atol=1e-3)


def test_the_way_to_a_contact_on_the_far_side_goes_around_the_block(targets):
    # the same block with the disc beyond the stem's tip: the contact it needs is behind the block, so each
    # target on the way stays clear of the T by more than the disc's radius
    pose = np.array([*_plane(GOAL, (0.0, -20.0)), GOAL[2]], np.float32)
    pushers = np.stack([_plane(pose, (x, 150.0)) for x in (-20.0, 0.0, 20.0)]).astype(np.float32)
    got = np.asarray(targets(jnp.asarray(pushers), jnp.asarray(np.repeat(pose[None], 3, 0))))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    body = (got - pose[:2]) @ np.array([[c, -s], [s, c]])  # back into the block's frame
    for point in body:
        gaps = [np.hypot(*(point - np.clip(point, box[0::2], box[1::2]))) for box in pusht.geometry.BOXES]
        assert min(gaps) > 15.0, (point, gaps)
    for a, b in zip(pushers, got, strict=True):  # and the straight line to each target misses it too
        for t in np.linspace(0, 1, 21):
            q = (a + t * (b - a) - pose[:2]) @ np.array([[c, -s], [s, c]])
            assert min(np.hypot(*(q - np.clip(q, box[0::2], box[1::2]))) for box in pusht.geometry.BOXES) > 15.0


@pytest.fixture(scope="module")
def starts():
    """Eight eval starts of the state arena, reset once: their info and privileged state."""
    arena = jarena.build_arena(STATE)

    @jax.jit
    def reset(episodes):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(episodes)
        return info, jax.vmap(arena.privileged)(state)

    return arena, *reset(jnp.arange(8))


def test_the_same_actions_for_any_key_and_batch(starts):
    arena, info, privileged = starts
    oracle = build_agent("oracle_pusht")

    @jax.jit
    def first_actions(info, privileged, key):
        state = oracle.init(key, arena.spec, info.reward.shape[0])
        return oracle.act(state, info, key, privileged)[0]

    take = jax.jit(lambda tree, index: jax.tree_util.tree_map(lambda x: x[index], tree))
    whole = np.asarray(first_actions(info, privileged, jax.random.key(0)))
    assert whole.shape == (8, 2) and len(np.unique(whole, axis=0)) == 8
    np.testing.assert_array_equal(np.asarray(first_actions(info, privileged, jax.random.key(7))), whole)
    for part in (np.array([5]), np.array([6, 1, 3]), np.arange(8)[::-1]):
        got = first_actions(take(info, part), take(privileged, part), jax.random.key(1))
        np.testing.assert_array_equal(np.asarray(got), whole[part])


def test_covers_the_goal_on_eval_episodes(evaluate_first_episodes):
    result = evaluate_first_episodes("oracle_pusht", STATE, episodes=16)
    assert np.all(result.successes), result.successes
    lengths = np.asarray(result.lengths)
    assert lengths.max() < 200 and lengths.mean() < 120, lengths  # well inside the 300 actions
    assert np.all(np.asarray(result.metrics["coverage"]) > 0.95)
