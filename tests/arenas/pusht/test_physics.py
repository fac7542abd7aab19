"""PushT's physics: the PD-driven pusher, a block that moves only when pushed, and agreement with pymunk.

Every scene runs in one jitted, vmapped rollout of 100 actions (one compiled program for the module).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.pusht import geometry, physics
from tests.arenas.pusht.reference import rollout as pymunk_rollout

STEPS = 100
CHECKPOINTS = (10, 50, 100)


def _line(start, end, steps):
    """Targets moving evenly from ``start`` to ``end`` over ``steps`` actions."""
    return np.linspace(start, end, steps + 1)[1:]


def _hold(point, steps):
    return np.tile(np.asarray(point, np.float64), (steps, 1))


def _wander(seed):
    """A random pushing sequence away from the walls: the pusher starts 110 units from the block's centre and
    heads through it, turning a little each action and back towards the block every 30 actions."""
    rng = np.random.default_rng(seed)
    pose = np.array([rng.uniform(200, 310), rng.uniform(200, 310), rng.uniform(-np.pi, np.pi)])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    centre = pose[:2] + np.array([[c, -s], [s, c]]) @ np.array(geometry.CENTRE_OF_GRAVITY)
    heading = rng.uniform(-np.pi, np.pi)
    start = centre - 110 * np.array([np.cos(heading), np.sin(heading)])
    point, actions = start.copy(), []
    for t in range(STEPS):
        heading += rng.normal(0, 0.15)
        point = np.clip(point + rng.uniform(5, 15) * np.array([np.cos(heading), np.sin(heading)]), 60, 452)
        if t % 30 == 29:
            heading = np.arctan2(*(centre - point)[::-1])
        actions.append(point.copy())
    return start, pose, np.array(actions)


# name -> (pusher start (2,), block pose (3,), targets (STEPS, 2))
SCENES = {
    # the pusher alone, far from the block: it settles on a target and the block never moves
    "track": ((100.0, 100.0), (380.0, 380.0, 0.3), _hold((400.0, 300.0), STEPS)),
    # around the block without touching it (the T reaches 121 units from its origin)
    "circle": ((256.0 + 160.0, 256.0), (256.0, 256.0, 1.0),
               256.0 + 160.0 * np.stack([np.cos(np.linspace(0, 2 * np.pi, STEPS)),
                                         np.sin(np.linspace(0, 2 * np.pi, STEPS))], -1)),
    # the bar's outer edge pushed square on: the block slides along, then stays where it was left
    "bar": ((256.0, 150.0), (256.0, 200.0, 0.0),
            np.concatenate([_line((256.0, 150.0), (256.0, 300.0), 60), _line((256.0, 300.0), (256.0, 230.0), 10),
                            _hold((256.0, 230.0), 30)])),
    # the stem's tip pushed sideways: the block turns
    "stem": ((150.0, 300.0), (256.0, 190.0, 0.0), _line((150.0, 300.0), (330.0, 300.0), STEPS)),
    # into the T's inner corner under the bar, where the disc touches both boxes
    "corner": ((180.0, 320.0), (256.0, 200.0, 0.0),
               np.concatenate([_line((180.0, 320.0), (226.0, 245.0), 40), _line((226.0, 245.0), (300.0, 240.0), 60)])),
    # against the left wall, then away
    "wall": ((200.0, 260.0), (120.0, 200.0, np.pi / 2),
             np.concatenate([_line((200.0, 260.0), (70.0, 260.0), 70), _line((70.0, 260.0), (200.0, 260.0), 30)])),
    **{f"wander{seed}": _wander(seed) for seed in range(4)},
}


@pytest.fixture(scope="module")
def rollouts():
    """name -> (block poses (STEPS, 3), pusher positions (STEPS, 2), block speeds (STEPS,)) of every scene."""
    params = jax.tree_util.tree_map(jnp.float32, physics.PushTParams())

    def run(pusher, pose, targets):
        def body(state, target):
            state = physics.step(state, target, params)
            speed = jnp.abs(state.block_velocity).sum() + jnp.abs(state.block_spin)
            return state, (physics.block_pose(state), state.pusher, speed)

        return jax.lax.scan(body, physics.place(pusher, pose, params), targets)[1]

    names = list(SCENES)
    batch = [jnp.asarray(np.stack([np.asarray(SCENES[n][i], np.float32) for n in names])) for i in range(3)]
    out = jax.device_get(jax.jit(jax.vmap(run))(*batch))
    return {n: tuple(np.asarray(x[i]) for x in out) for i, n in enumerate(names)}


def test_pusher_tracks_its_target_without_overshoot(rollouts):
    """k_p = 100, k_v = 20 is critically damped: the pusher settles on the target and never passes it."""
    _, pusher, _ = rollouts["track"]
    np.testing.assert_allclose(pusher[-1], [400.0, 300.0], atol=1e-2)
    assert np.all(np.diff(pusher[:, 0]) >= -1e-4) and np.all(pusher[:, 0] <= 400.0 + 1e-3)
    assert np.all(np.diff(pusher[:, 1]) >= -1e-4) and np.all(pusher[:, 1] <= 300.0 + 1e-3)
    assert np.linalg.norm(pusher[9] - [400.0, 300.0]) < 0.05 * np.linalg.norm([300.0, 200.0])  # within 1 s


def test_block_moves_only_when_touched(rollouts):
    for name, pose in (("track", (380.0, 380.0, 0.3)), ("circle", (256.0, 256.0, 1.0))):
        block, _, _ = rollouts[name]
        np.testing.assert_array_equal(block, np.tile(np.float32(pose), (STEPS, 1)), err_msg=name)
    block, _, speed = rollouts["bar"]
    assert block[59, 1] > 300.0  # pushed along y ahead of the disc (at y = 300, radius 15), without turning
    np.testing.assert_allclose(block[59, [0, 2]], [256.0, 0.0], atol=1e-3)
    # damping 0: once the pusher draws back the block keeps no velocity and stays put
    np.testing.assert_array_equal(block[62:], np.tile(block[62], (STEPS - 62, 1)))
    assert np.all(speed[62:] == 0)
    block, _, _ = rollouts["stem"]
    assert abs(block[-1, 2]) > 0.3  # a push on the stem's tip turns the block


def test_walls_hold_the_block(rollouts):
    block, _, _ = rollouts["wall"]
    hull_x = np.cos(block[:, 2:]) * geometry.HULL[:, 0] - np.sin(block[:, 2:]) * geometry.HULL[:, 1] + block[:, :1]
    # squeezed by the disc, the block overlaps the wall's face (x = 7) by a few units, as in pymunk, but stays out
    assert 7.0 - 5.0 < hull_x.min() < 7.0 + 1.0


@pytest.mark.parametrize("name", [n for n in SCENES if n not in ("track", "circle")])
def test_block_follows_pymunk(rollouts, name):
    """The same targets in a pymunk scene built from pusht_env's facts: the block's pose agrees after 10, 50
    and 100 actions."""
    block, pusher, _ = rollouts[name]
    start, pose, targets = SCENES[name]
    ref_block, ref_pusher = pymunk_rollout(start, pose, targets)
    np.testing.assert_allclose(pusher, ref_pusher, atol=1e-2)
    for t in CHECKPOINTS:
        position = np.linalg.norm(block[t - 1, :2] - ref_block[t - 1, :2])
        angle = abs(block[t - 1, 2] - ref_block[t - 1, 2])
        assert position < 0.05 and angle < 1e-3, f"{name} after {t} actions: {position:.4f} units, {angle:.5f} rad"
