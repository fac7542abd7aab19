"""Ravens' tasks beyond block-insertion: the oracle's episodes, and the goals and their partial credit.

Each task's oracle episode is one compiled program (a reset and a scan of oracle actions over Ravens' step
limit, for eval episode 0, with XLA's quick options); the scoring checks are pure functions of hand-placed
objects, compiled without the physics step.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.raven import physics, scoring, tasks
from jarena.arenas.raven.scene import build_scene
from tests.arenas.raven import FAST_COMPILE

# Ravens' max_steps, and the actions the oracle needs at most (the actions run, to keep the test short)
EPISODES = {"place-red-in-green": (10, 3), "align-box-corner": (3, 1), "stack-block-pyramid": (12, 6),
            "towers-of-hanoi": (14, 7)}


def _oracle_episode(arena, oracle, steps):
    """The rewards, successes and stages complete after each of ``steps`` oracle actions of eval episode 0 (the
    rewards of an episode once it is over count as 0)."""
    state, info = arena.reset(None, episode=jnp.asarray(0))
    agent = oracle.init(jax.random.key(0), arena.spec, 1)

    def one(carry, _):
        state, info, done = carry
        action, _ = oracle.act(agent, info, jax.random.key(0), arena.privileged(state))
        state, info = arena.step(state, action)
        out = (jnp.where(done, 0.0, info.reward), info.success & ~done, info.metrics["stages"])
        return (state, info, done | info.terminated | info.truncated), out

    _, (reward, success, stages) = jax.lax.scan(one, (state, info, jnp.asarray(False)), None, length=steps)
    return reward, success, stages


@pytest.mark.parametrize("task", list(EPISODES))
def test_the_oracle_succeeds_with_ravens_partial_credit(task):
    max_steps, needed = EPISODES[task]
    arena = jarena.build_arena(f"raven|task:{task}")
    assert arena.max_episode_steps == max_steps
    oracle = jarena_agents.build_agent("oracle_raven")
    run = jax.jit(functools.partial(_oracle_episode, arena, oracle, needed), compiler_options=FAST_COMPILE)
    reward, success, stages = (np.asarray(x) for x in run())
    assert success.any() and reward.sum() == pytest.approx(1.0, abs=1e-5)
    actions = int(np.argmax(success)) + 1
    credit = reward[:actions]
    if task == "stack-block-pyramid":  # 1/2 for three blocks, 1/3 for two, 1/6 for one: 1/6 a block
        np.testing.assert_allclose(credit, [1 / 6] * 6, atol=1e-5)
        assert stages[:6].tolist() == [0, 0, 1, 1, 2, 3]
    elif task == "towers-of-hanoi":  # seven moves of 1/7
        np.testing.assert_allclose(credit, [1 / 7] * 7, atol=1e-5)
        assert stages[:7].tolist() == list(range(1, 8))
    elif task == "align-box-corner":
        assert credit.tolist() == pytest.approx([1.0])
    else:  # one red block a step, each 1 / (red blocks)
        np.testing.assert_allclose(credit, 1.0 / actions, atol=1e-5)


@functools.cache
def _scene(task):
    """A task, its initial (parked) physics and objects' positions, and its jitted goal and score."""
    spec = tasks.TASKS[task]()
    dynamics = physics.raven_dynamics(build_scene(spec.items))

    @jax.jit
    def parked_start():
        start = dynamics.init(None, None)
        return start, physics.object_poses(start)[0]

    start, parked = parked_start()
    params = scoring.PoseGoalParams(pos_eps=spec.pos_eps)

    @jax.jit
    def goal_and_score(start, pos, yaw, stage, progress):
        placed = physics.place_objects(start, pos, jax.vmap(lambda y: jnp.asarray(
            [jnp.cos(y / 2), 0.0, 0.0, jnp.sin(y / 2)]))(yaw))
        goal = spec.goal(placed)
        return goal, scoring.score(scoring.planar_poses(placed), goal, params, stage, progress)

    return start, np.asarray(parked), goal_and_score


def _score(task, placed: dict, stage=0, progress=0.0):
    """The goal (on the host) and the score with objects (scene index -> (x, y, z, yaw)) placed by hand, the others
    parked."""
    start, parked, goal_and_score = _scene(task)
    pos, yaw = parked.copy(), np.zeros(len(parked), np.float32)
    for i, (x, y, z, theta) in placed.items():
        pos[i], yaw[i] = (x, y, z), theta
    goal, value = goal_and_score(start, pos, yaw, stage, progress)
    return jax.tree_util.tree_map(np.asarray, goal), float(value)


def test_red_blocks_score_in_any_green_bowl_within_5_cm():
    """Red blocks 0-2 are objects 0-2, green bowls 0-2 the last three (23-25); two bowls and two blocks here."""
    bowls = {23: (0.4, -0.2, 0.0, 0.3), 24: (0.6, 0.2, 0.0, 1.0)}
    off = lambda d, yaw=0.0: (0.4 + d, -0.2, 0.02, yaw)  # noqa: E731
    goal, value = _score("place-red-in-green", {**bowls, 0: off(0.049, 2.0), 1: off(0.2)})
    assert goal.present.tolist() == [True, True, False] and goal.target_present.tolist() == [True, True, False]
    assert value == 0.5  # one of two blocks in a bowl, at any heading
    assert _score("place-red-in-green", {**bowls, 0: off(0.051), 1: off(0.2)})[1] == 0.0
    both_in_one = {**bowls, 0: off(0.02), 1: off(-0.02, 0.7)}  # each block counts on its own, as in Ravens
    assert _score("place-red-in-green", both_in_one)[1] == 1.0
    # a distractor (object 3, a block) in a bowl counts for nothing
    assert _score("place-red-in-green", {**bowls, 0: off(0.2), 1: off(0.3), 3: off(0.0)})[1] == 0.0


def test_a_box_aligns_with_its_corner_in_four_poses():
    """The box (object 0, here of the scene's largest size, 15 x 15 cm) matches any of Ravens' four target poses,
    its heading counted in full; each of the four poses of a 12 x 8 cm box puts a corner of it on the marks'."""
    corner = (0.5, 0.1, 0.0, 0.4)
    goal, _ = _score("align-box-corner", {1: corner})
    targets = np.asarray(goal.targets)
    for x, y, _, yaw in targets:
        assert _score("align-box-corner", {1: corner, 0: (x, y, 0.03, yaw)})[1] == 1.0
    x, y, _, yaw = targets[0]
    assert _score("align-box-corner", {1: corner, 0: (x, y, 0.03, yaw + np.deg2rad(14))})[1] == 1.0
    assert _score("align-box-corner", {1: corner, 0: (x, y, 0.03, yaw + np.pi / 4)})[1] == 0.0
    assert _score("align-box-corner", {1: corner, 0: (x + 0.011, y, 0.03, yaw)})[1] == 0.0
    # a 12 x 8 cm box in each target pose has a corner on the marks' corner, at (6, 4) cm in the corner's frame
    size = np.asarray([0.12, 0.08, 0.04], np.float32)
    cos, sin = np.cos(corner[3]), np.sin(corner[3])
    marks_corner = np.asarray(corner[:2]) + np.asarray([[cos, -sin], [sin, cos]]) @ np.asarray([0.06, 0.04])
    corner_targets, marks = (np.asarray(x) for x in jax.jit(lambda corner, size: (
        tasks.corner_targets(corner, size), tasks.corner_marks(size)))(np.asarray(corner, np.float32), size))
    for x, y, _, yaw in corner_targets:
        signs = np.asarray([[1, 1], [1, -1], [-1, 1], [-1, -1]]) * np.asarray([0.06, 0.04])
        rotation = np.asarray([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        box_corners = np.asarray([x, y]) + signs @ rotation.T
        assert np.min(np.linalg.norm(box_corners - marks_corner, axis=-1)) < 1e-6
    np.testing.assert_allclose(marks, [[0.0375, 0.0425, 0.0], [0.0625, 0.0175, 0.0]], atol=1e-7)


def test_a_pyramid_scores_row_by_row():
    """Blocks 0-2 (purple, blue, green) go in the bottom row, 3-4 (yellow, orange) above, 5 (red) on top; the stand
    is object 6. Only the current row scores; a quarter turn is no turn."""
    stand = (0.5, 0.0, 0.0025, 0.3)
    goal, _ = _score("stack-block-pyramid", {6: stand})
    targets = np.asarray(goal.targets)
    at = lambda k, turn=0.0: (*targets[k, :3], targets[k, 3] + turn)  # noqa: E731
    assert _score("stack-block-pyramid", {6: stand, 0: at(2), 1: at(0, np.pi / 2)})[1] == pytest.approx(1 / 3)
    bottom = {6: stand, 0: at(0), 1: at(1), 2: at(2)}
    assert _score("stack-block-pyramid", bottom)[1] == pytest.approx(1 / 2)
    # the top block in its place counts only in the last stage
    assert _score("stack-block-pyramid", {**bottom, 5: at(5)})[1] == pytest.approx(1 / 2)
    assert _score("stack-block-pyramid", {**bottom, 3: at(4)}, stage=1, progress=0.5)[1] == pytest.approx(
        1 / 2 + 1 / 6)
    assert _score("stack-block-pyramid", {**bottom, 5: at(5)}, stage=2, progress=5 / 6)[1] == pytest.approx(1.0)
    # a bottom block in the middle row scores nothing there
    assert _score("stack-block-pyramid", {**bottom, 0: at(3)}, stage=1, progress=0.5)[1] == pytest.approx(0.5)


def test_hanoi_credits_each_move_in_ravens_order():
    assert tasks.hanoi_moves() == [(0, 0, 2), (1, 0, 1), (0, 2, 1), (2, 0, 2), (0, 1, 0), (1, 1, 2), (0, 0, 2)]
    stand = (0.5, 0.0, 0.005, 0.0)
    rod = lambda k, dx=0.0: (0.5 + dx, tasks.RODS[k], 0.02, 1.3)  # noqa: E731
    goal, _ = _score("towers-of-hanoi", {3: stand})
    assert np.asarray(goal.objects).tolist() == [0, 1, 0, 2, 0, 1, 0]
    assert _score("towers-of-hanoi", {3: stand, 0: rod(2, 0.009)})[1] == pytest.approx(1 / 7)  # any heading
    assert _score("towers-of-hanoi", {3: stand, 0: rod(2, 0.011)})[1] == 0.0
    assert _score("towers-of-hanoi", {3: stand, 0: rod(1)})[1] == 0.0  # the wrong rod for the first move
    assert _score("towers-of-hanoi", {3: stand, 0: rod(1)}, stage=2, progress=2 / 7)[1] == pytest.approx(3 / 7)
