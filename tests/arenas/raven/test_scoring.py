"""Ravens' pose scoring: the match tolerances, heading symmetry, partial credit and the reward of an episode."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.raven import scoring
from jarena.arenas.raven.physics import place_objects, raven_dynamics
from jarena.arenas.raven.scene import ELL, FIXTURE, Item, build_scene
from jarena.arenas.raven.scoring import Goal, PoseGoalParams

TARGET = (0.5, 0.1, 0.02, 0.3)


def _goal(objects=1, symmetry=2 * np.pi, present=None) -> Goal:
    """A goal for ``objects`` objects (scene indices 0, 1, ...), each allowed on its own target at ``TARGET``."""
    return Goal(objects=np.arange(objects, dtype=np.int32),
                present=np.ones(objects, bool) if present is None else np.asarray(present),
                symmetry=np.full(objects, symmetry, np.float32),
                targets=np.asarray([TARGET] * objects, np.float32), target_present=np.ones(objects, bool),
                matches=np.eye(objects, dtype=bool))


def _at(distance=0.0, turn=0.0, angle=np.pi / 4):
    """float32 (4,): a pose ``distance`` metres from the target along ``angle`` and turned ``turn`` radians."""
    x, y, z, yaw = TARGET
    return np.asarray([x + distance * np.cos(angle), y + distance * np.sin(angle), z, yaw + turn], np.float32)


_score = jax.jit(scoring.score)


@pytest.mark.parametrize("distance, turn, placed", [
    (0.009, 0.0, 1.0), (0.011, 0.0, 0.0),  # under 1 cm matches, over it does not
    (0.0, np.deg2rad(14), 1.0), (0.0, np.deg2rad(16), 0.0),  # under 15 degrees matches, over it does not
    (0.0, np.deg2rad(-14) + 2 * np.pi, 1.0),  # a full turn is no turn
])
def test_a_pose_matches_within_1_cm_and_15_degrees(distance, turn, placed):
    planar = _at(distance, turn)[None]
    assert float(_score(planar, _goal(), PoseGoalParams())) == placed


def test_heading_errors_count_modulo_the_symmetry():
    error = jax.jit(scoring.heading_error)
    degrees = lambda yaw, target, symmetry: float(np.rad2deg(error(np.deg2rad(yaw), np.deg2rad(target), symmetry)))
    assert degrees(350.0, 0.0, 2 * np.pi) == pytest.approx(10.0, abs=1e-3)  # the L: no symmetry
    assert degrees(180.0, 0.0, 2 * np.pi) == pytest.approx(180.0, abs=1e-3)
    assert degrees(85.0, 0.0, np.pi / 2) == pytest.approx(5.0, abs=1e-3)  # a square: quarter turns are the same
    assert degrees(190.0, 0.0, np.pi) == pytest.approx(10.0, abs=1e-3)
    assert degrees(123.0, 0.0, 0.0) == 0.0  # symmetry 0: any heading
    # a square turned 80 degrees matches its target (10 degrees off), the L turned 80 degrees does not
    assert float(_score(_at(0.0, np.deg2rad(80.0))[None], _goal(symmetry=np.pi / 2), PoseGoalParams())) == 1.0
    assert float(_score(_at(0.0, np.deg2rad(80.0))[None], _goal(), PoseGoalParams())) == 0.0


def test_partial_credit_counts_the_present_objects():
    placed_and_not = np.stack([_at(0.0), _at(0.05)])
    assert float(_score(placed_and_not, _goal(2), PoseGoalParams())) == 0.5
    assert float(_score(placed_and_not, _goal(2, present=[True, False]), PoseGoalParams())) == 1.0
    # the tolerance is a param: 5 cm (place-red-in-green's) accepts the second
    assert float(_score(placed_and_not, _goal(2), PoseGoalParams(pos_eps=0.051))) == 1.0


def test_an_episodes_rewards_add_up_to_its_score():
    """The block-insertion task over hand-placed blocks: the reward is the change of the score, success and
    termination come with a full score, and a block moved off its target once the goal is complete (at rest)
    keeps its credit, as Ravens banks a complete goal; while it still moves (5 mm/s or more) the goal is not
    complete and moving it off takes the credit back."""
    scene = build_scene((Item("ell", ELL), Item("fixture", FIXTURE)))
    task = scoring.pose_goal(lambda p: Goal(objects=jnp.asarray([0]), present=jnp.ones(1, bool),
                                            symmetry=jnp.asarray([2 * np.pi], jnp.float32),
                                            targets=scoring.planar_poses(p)[1:2], target_present=jnp.ones(1, bool),
                                            matches=jnp.ones((1, 1), bool)), "block-insertion")
    physics = jax.jit(raven_dynamics(scene).init)(None, None)
    fixture = jnp.asarray([[0.5, 0.1, 0.02]])
    quat = jnp.asarray([[np.cos(0.15), 0.0, 0.0, np.sin(0.15)]] * 2, jnp.float32)  # yaw 0.3, as TARGET

    @jax.jit
    def rewards(block_xy, speed):  # (S, 2): the block's position at each step; its speed, m/s
        def at(xy):
            placed = place_objects(physics, jnp.concatenate([jnp.concatenate([xy, jnp.asarray([0.02])])[None],
                                                             fixture]), quat)
            return placed.replace(data=placed.data.replace(qvel=placed.data.qvel.at[0].set(speed)))

        from jarena.core.types import Outcome, Transition
        params = task.default_params()
        _, state = task.reset(None, at(block_xy[0]), Outcome.empty(), params)
        out = []
        for xy in block_xy[1:]:
            outcome, state = task.update(state, Outcome.empty(), Transition(None, None, at(xy)), params)
            out.append((outcome.reward, outcome.success, outcome.terminated, outcome.metrics["placed"]))
        return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *out)

    step = 0.009 / np.sqrt(2)
    path = jnp.asarray([[0.3, -0.2], [0.35, -0.2], [0.5 + step, 0.1 + step], [0.3, 0.2]], jnp.float32)
    reward, success, terminated, placed = (np.asarray(x) for x in rewards(path, 0.0049))
    np.testing.assert_allclose(reward, [0.0, 1.0, 0.0])
    assert success.tolist() == [False, True, True] and terminated.tolist() == [False, True, True]
    assert placed.tolist() == [0.0, 1.0, 1.0] and reward.sum() == 1.0
    reward, success, terminated, placed = (np.asarray(x) for x in rewards(path, 0.0051))
    np.testing.assert_allclose(reward, [0.0, 1.0, -1.0])
    assert success.tolist() == [False, True, False] and terminated.tolist() == [False, True, False]
