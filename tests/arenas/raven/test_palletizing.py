"""Raven's palletizing-boxes: the stack's places, boxes coming in one at a time, the zone score and the oracle.

One compiled program (XLA's quick options) resets eval episode 0 and runs the oracle for its 18 actions, then one
scripted action that puts the last box half on its neighbour; the spawn checks on hand-set scenes and the zone
scores of hand-placed boxes are compiled without the physics step.
"""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.raven import heightmap, physics, scoring, tasks
from tests.arenas.raven import FAST_COMPILE

ARENA = "raven|task:palletizing-boxes"
BOXES = 18
ACTIONS = BOXES + 1
SPAWN = (0.5, -0.25)
# (0.19 - (2, 3, 3) margins of 1 cm) / (2, 3, 3), the first layer transposed: 5.67 x 9 x 5.67 cm, the middle one
# 9 x 5.67 x 5.67 cm
SHORT, LONG = (0.19 - 0.02) / 3, (0.19 - 0.01) / 2


def _workspace(planar):
    """bool (..., 18): the boxes in the workspace where boxes come in (y in [-0.5, 0])."""
    return (planar[..., :BOXES, 1] >= -0.5) & (planar[..., :BOXES, 1] <= 0.0)


def _nudge(state):
    """The last box placed, picked at its centre and put back 3 cm along x towards the middle of its row: 2 cm of
    it over its neighbour's place, its centre over the gap between them."""
    planar = scoring.planar_poses(state.physics)
    xy = planar[state.physics.queue.order[BOXES - 1], :2]
    place = xy + jnp.asarray([jnp.where(xy[0] > 0.5, -0.03, 0.03), 0.0])
    return jnp.concatenate([heightmap.world_to_pixel(xy), heightmap.world_to_pixel(place), jnp.zeros(1)])


@pytest.fixture(scope="module")
def pallet():
    """The arena, a start of eval episodes 0, 0 and 1, and the 19 actions of episode 0 in one program (the oracle's
    18, then :func:`_nudge`): per action the reward, termination, success, boxes come in so far, every object's
    pose and the height at the spawn point."""
    arena = jarena.build_arena(ARENA)
    oracle = jarena_agents.build_agent("oracle_raven")
    spawn_pixel = tuple(int(round(float(v))) for v in heightmap.world_to_pixel(jnp.asarray(SPAWN)))

    def run(episode):
        state, info = arena.reset(None, episode=episode)
        agent = oracle.init(jax.random.key(0), arena.spec, 1)

        def one(carry, _):
            state, info, done = carry
            action, _ = oracle.act(agent, info, jax.random.key(0), arena.privileged(state))
            state, info = arena.step(state, jnp.where(state.step == BOXES, _nudge(state), action))
            out = (jnp.where(done, 0.0, info.reward), info.terminated, info.success, state.physics.queue.count,
                   scoring.planar_poses(state.physics), info.observation["height"][spawn_pixel])
            return (state, info, done | info.terminated | info.truncated), out

        (state, _, _), steps = jax.lax.scan(one, (state, info, jnp.asarray(False)), None, length=ACTIONS)
        return state, steps

    def starts(episodes):
        states, infos = jax.vmap(lambda e: arena.reset(None, episode=e))(episodes)
        return states.physics.queue, jax.vmap(scoring.planar_poses)(states.physics), infos.observation["height"]

    state, steps = jax.jit(run, compiler_options=FAST_COMPILE)(jnp.asarray(0))
    queues, planar, heights = jax.jit(starts, compiler_options=FAST_COMPILE)(jnp.asarray([0, 0, 1]))
    host = lambda tree: jax.tree_util.tree_map(np.asarray, tree)  # noqa: E731
    reward, terminated, success, count, poses, spawn_height = host(steps)
    return SimpleNamespace(arena=arena, state=state, queues=host(queues), planar=host(planar),
                           heights=host(heights), spawn_pixel=spawn_pixel, reward=reward, terminated=terminated,
                           success=success, count=count, poses=poses, spawn_height=spawn_height,
                           goal=host(scoring.goal_state(state.task).goal))


def test_the_stack_places_follow_ravens_transposed_layers():
    """Hand values of Ravens' formula, ((x, y, z) + 0.5) * box + (x, y, z) * 1 cm - (9.5, 9.5, -3) cm, in the
    pallet's frame at (0.5, 0.25, 0.02); every layer transposes the grid first (3 x 2, then 2 x 3, then 3 x 2)."""
    centres, sizes = tasks.stack_places()
    assert centres.shape == (BOXES, 3)
    np.testing.assert_allclose(sizes[:6], [[SHORT, LONG, SHORT]] * 6, atol=1e-12)
    np.testing.assert_allclose(sizes[6:12], [[LONG, SHORT, SHORT]] * 6, atol=1e-12)
    np.testing.assert_allclose(sizes[12:], sizes[:6], atol=1e-12)
    hand = {0: (0.5 * SHORT - 0.095, 0.5 * LONG - 0.095, 0.5 * SHORT + 0.03),  # layer 0: x, y = 0, 0
            1: (1.5 * SHORT + 0.01 - 0.095, 0.5 * LONG - 0.095, 0.5 * SHORT + 0.03),  # x, y = 1, 0
            5: (2.5 * SHORT + 0.02 - 0.095, 1.5 * LONG + 0.01 - 0.095, 0.5 * SHORT + 0.03),  # x, y = 2, 1
            6: (0.5 * LONG - 0.095, 0.5 * SHORT - 0.095, 1.5 * SHORT + 0.04),  # layer 1: x, y = 0, 0
            9: (1.5 * LONG + 0.01 - 0.095, 1.5 * SHORT + 0.01 - 0.095, 1.5 * SHORT + 0.04),  # x, y = 1, 1
            17: (2.5 * SHORT + 0.02 - 0.095, 1.5 * LONG + 0.01 - 0.095, 2.5 * SHORT + 0.05)}  # layer 2: 2, 1
    for box, centre in hand.items():
        np.testing.assert_allclose(centres[box], centre, atol=1e-12, err_msg=f"box {box}")
    np.testing.assert_allclose(centres[5], [0.06667, 0.05, 0.05833], atol=1e-5)
    np.testing.assert_allclose(centres[9], [0.05, 0.0, 0.125], atol=1e-5)
    # Ravens' 2 cm grid of points: 3 x 5 x 3 on every box
    assert tasks.box_points(sizes[0]).shape == (45, 3) and tasks.box_points(sizes[6]).shape == (45, 3)
    np.testing.assert_allclose(np.unique(tasks.box_points(sizes[0])[:, 1]), [-0.045, -0.025, -0.005, 0.015, 0.035],
                               atol=1e-7)


def test_boxes_come_in_one_at_a_time_in_a_fixed_bottom_up_order(pallet):
    queue, planar = pallet.queues, pallet.planar
    order = queue.order[0]
    # episode 0 twice the same; episode 1 another order; each layer whole before the next, from the bottom
    np.testing.assert_array_equal(queue.order[1], order)
    assert not np.array_equal(queue.order[2], order)
    for q in (order, queue.order[2]):
        for layer in range(3):
            assert sorted(q[6 * layer:6 * layer + 6].tolist()) == list(range(6 * layer, 6 * layer + 6))
    # at the start: one box in the workspace, the first of the order, at rest on the table at the spawn point
    assert queue.count.tolist() == [1, 1, 1]
    for i in range(3):
        assert np.flatnonzero(_workspace(planar[i])).tolist() == [queue.order[i, 0]]
        first = planar[i, queue.order[i, 0]]
        np.testing.assert_allclose(first[:3], [*SPAWN, SHORT / 2], atol=1e-6)
        turn = first[3] - queue.yaw[i, 0]
        assert abs(np.mod(turn + np.pi, 2 * np.pi) - np.pi) < 1e-5
        assert np.all(planar[i, :BOXES][~_workspace(planar[i]), 0] > 1.5)  # the others parked off the table
    np.testing.assert_allclose(planar[0, BOXES], [0.5, 0.25, 0.02, 0.0], atol=1e-7)  # the pallet
    r, c = pallet.spawn_pixel
    assert pallet.heights[0, r, c] == pytest.approx(SHORT, abs=1e-5)  # seen from above
    # after each placement the next box is there, until the last
    poses = pallet.poses
    for k in range(BOXES):
        inside = np.flatnonzero(_workspace(poses[k]))
        if k < BOXES - 1:
            assert inside.tolist() == [order[k + 1]] and pallet.count[k] == k + 2, f"after action {k}"
            np.testing.assert_allclose(poses[k, order[k + 1], :2], SPAWN, atol=2e-4)
            assert pallet.spawn_height[k] == pytest.approx(SHORT, abs=5e-4)
        else:
            assert inside.size == 0 and pallet.count[k] == BOXES and pallet.spawn_height[k] == 0.0


def test_the_oracle_stacks_all_eighteen_boxes(pallet):
    """Each action puts the box that came in at its place (1/18 of the score each, within a millimetre); the
    eighteenth completes the stack: success, and the episode ends."""
    np.testing.assert_allclose(pallet.reward[:BOXES], 1 / BOXES, atol=1e-5)
    assert pallet.reward.sum() == pytest.approx(1.0, abs=1e-5)
    assert pallet.success[:BOXES - 1].tolist() == [False] * (BOXES - 1) and bool(pallet.success[BOXES - 1])
    assert pallet.terminated[:BOXES - 1].tolist() == [False] * (BOXES - 1) and bool(pallet.terminated[BOXES - 1])
    order, targets = pallet.queues.order[0], pallet.goal.targets
    for k in range(BOXES):
        box = order[k]
        np.testing.assert_allclose(pallet.poses[k, box, :2], targets[box, :2], atol=1e-3, err_msg=f"box {box}")
    final = pallet.poses[BOXES - 1]
    np.testing.assert_allclose(final[:BOXES, :2], targets[:, :2], atol=1e-3)  # the stack stays put
    assert np.all(np.abs(final[:BOXES, 3]) < np.deg2rad(1.0))
    # resting on the pallet (its top 3.9 cm up) and on each other, without Ravens' 1 cm between layers (the cup
    # lowers each box until it touches), the soft contacts giving a fraction of a millimetre under each layer
    np.testing.assert_allclose(final[:BOXES, 2], 0.02 + 0.0375 / 2 + (np.arange(BOXES) // 6 + 0.5) * SHORT,
                               atol=1e-3)


def test_spawning_waits_for_an_empty_workspace_and_ends_the_episode_after_the_last_box(pallet):
    """The task's hook on hand-set scenes: with a box in the workspace nothing comes; with the workspace empty the
    next box of the order comes in; once every box has come in, the next action ends the episode."""
    hook = tasks.palletizing_boxes().after_action
    start = pallet.state.physics  # after the episode: every box on the pallet, all 18 come in
    order = np.asarray(start.queue.order)

    @jax.jit
    def cases(start):
        back = start.replace(queue=start.queue.replace(count=jnp.asarray(5, jnp.int32)))
        in_workspace = physics.place_movable(back, jnp.asarray(order[5]), jnp.asarray([0.6, -0.3, SHORT / 2]),
                                             jnp.asarray([1.0, 0.0, 0.0, 0.0]))
        after = [hook(p) for p in (back, in_workspace, start)]
        return [(p.queue.count, scoring.planar_poses(p), over) for p, over in after]

    empty, busy, last = jax.tree_util.tree_map(np.asarray, cases(start))
    (empty_count, empty_planar, empty_over), (busy_count, busy_planar, busy_over), (_, _, over) = empty, busy, last
    assert empty_count == 6 and not empty_over
    np.testing.assert_allclose(empty_planar[order[5], :3], [*SPAWN, SHORT / 2], atol=1e-6)
    assert busy_count == 5 and not busy_over
    np.testing.assert_allclose(busy_planar[order[5], :2], [0.6, -0.3], atol=1e-6)
    assert bool(over)


def test_the_zone_scores_the_share_of_box_points_over_the_pallet(pallet):
    """Hand cases with Ravens' points (a 2 cm grid from -size / 2: x and z at -2.83, -0.83 and 1.17 cm, y at -4.5
    to 3.5 cm for a box of the first layer), each box 1/18 of the score."""
    goal, parked = pallet.goal, pallet.planar[0]
    params = scoring.PoseGoalParams()

    def placed(*boxes):
        planar = parked.copy()
        planar[:BOXES] = np.asarray(parked[:BOXES]) * [1, 1, 1, 0]
        for box, pose in boxes:
            planar[box] = pose
        return planar

    edge_x, edge_y = 0.5 + 0.15, 0.25 + 0.125
    cases = {
        "parked": (placed(), 0.0),
        "box 0 on the pallet": (placed((0, (0.45, 0.25, 0.07, 0.3))), 1 / 18),
        "centred on the x edge: 2 of 3 columns": (placed((0, (edge_x, 0.25, 0.07, 0.0))), 2 / 3 / 18),
        "turned a quarter over the y edge: 1 of 3": (placed((0, (0.5, edge_y + 0.01, 0.07, np.pi / 2))), 1 / 3 / 18),
        "held 0.33 m up: 1 of 3 rows under 0.3 m": (placed((0, (0.5, 0.25, 0.33, 0.0))), 1 / 3 / 18),
        "held 0.35 m up": (placed((0, (0.5, 0.25, 0.35, 0.0))), 0.0),
        "at the spawn point": (placed((3, (*SPAWN, 0.03, 0.0))), 0.0),
        "every box at its target": (placed(*((b, goal.targets[b]) for b in range(BOXES))), 1.0),
    }
    score = jax.jit(jax.vmap(lambda planar: scoring.score(planar, goal, params)))
    values = np.asarray(score(jnp.asarray(np.stack([planar for planar, _ in cases.values()]), jnp.float32)))
    for (name, (_, expected)), value in zip(cases.items(), values, strict=True):
        assert value == pytest.approx(expected, abs=1e-6), name


def test_boxes_touch_their_neighbours_in_the_stack(pallet):
    """Boxes touch the table and the pallet by their collision bits, and other boxes only through explicit pairs
    (65, not 153): the boxes above and below whose places overlap, and their neighbours in the layer, side by side
    or corner to corner. So a box put 3 cm off its place, 2 cm of it over its neighbour, is lowered onto the
    neighbour and tips off its edge (it would sink into it, upright, without the pair), as with every pair of boxes
    colliding."""
    import mujoco

    model = pallet.state.physics.scene.model
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[g]) for g in range(model.ngeom)]
    box_geoms = [g for g, n in enumerate(names) if n.startswith("box")]
    assert all(model.geom_contype[g] & model.geom_conaffinity[h] == 0 for g in box_geoms for h in box_geoms)
    centres, _ = tasks.stack_places()
    pairs = [tuple(sorted(int(names[g][3:]) for g in pair)) for pair in zip(model.pair_geom1, model.pair_geom2,
                                                                             strict=True)]
    assert model.npair == 65 and len(set(pairs)) == 65
    for a, b in pairs:
        step = np.abs(centres[a] - centres[b])
        if a // 6 == b // 6:  # neighbours: one place apart along x (6.67 cm), y (9 or 6.67 cm) or both
            assert np.all(step[:2] < 0.11) and np.any(step[:2] > 0.05), (a, b)
        else:  # the layer above, overlapping
            assert b // 6 == a // 6 + 1 and np.all(step[:2] < (SHORT + LONG) / 2), (a, b)
    assert sum(a // 6 == b // 6 for a, b in pairs) == 33  # 11 a layer of 15

    box = pallet.queues.order[0, BOXES - 1]
    before, after = pallet.poses[BOXES - 1, box], pallet.poses[BOXES, box]
    start = int(pallet.state.physics.scene.qpos_address[box])
    quat = np.asarray(pallet.state.physics.data.qpos[start + 3:start + 7])
    up = 1.0 - 2.0 * (quat[1] ** 2 + quat[2] ** 2)  # the z of the box's up axis
    assert up < np.cos(np.deg2rad(5.0)) or after[2] > before[2] + 0.005, (before, after, up)
