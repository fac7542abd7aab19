"""Raven's assembling-kits: the shapes, the splits' shapes, the layout, the score with symmetries and the oracle.

One compiled program (XLA's quick options) resets eval, val and training episodes and runs the oracle on an eval
and a training episode; the shapes, the splits and the scores of hand-placed objects need no physics.
"""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.raven import heightmap, kits, scoring, splits, tasks
from jarena.core import episodes
from tests.arenas.raven import FAST_COMPILE

ARENA = "raven|task:assembling-kits"
COUNT = kits.OBJECTS
EVAL, VAL, TRAIN = (0, 1, 0), (episodes.VAL_BASE,), (episodes.TRAIN_LOW, episodes.TRAIN_LOW + 7)
EPISODES = EVAL + VAL + TRAIN
ORACLE = (1, len(EPISODES) - 1)  # the oracle runs eval episode 1 and a training episode
ORACLE_ACTIONS = COUNT
RAVENS_SYMMETRY = [2, 2, 2 / 3, 1 / 2, 1 / 2, 2, 1, 2 / 5, 1, 1 / 2, 2 / 5, 0, 2, 2, 2, 2, 0, 1 / 3, 2, 2]  # x pi
RAVENS_EXTENTS = [(20.3, 28.4), (24.9, 28.5), (30, 30), (30, 30), (30, 30), (30, 30), (37.5, 30), (28.6, 27.2),
                  (37.5, 22.5), (30, 30), (28.8, 30.3), (30, 30), (22.7, 29.1), (23.5, 28.4), (16, 28.4), (30, 30),
                  (30, 30), (26, 30), (28.7, 26.4), (27, 28.4)]  # half extents of Ravens' meshes seen from above, mm


def _corners(centres, half, yaw):
    """float (B, 4, 2): the corners of boxes seen from above."""
    signs = np.asarray([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    local = signs[None] * half[:, None, :2]
    return centres[:, None, :2] + np.stack([cos * local[..., 0] - sin * local[..., 1],
                                            sin * local[..., 0] + cos * local[..., 1]], -1)


def _covered(points, centres, half, yaw):
    """bool (P,): which points (P, 2) lie in any of the boxes seen from above."""
    d = points[:, None, :] - centres[None, :, :2]
    cos, sin = np.cos(yaw)[None], np.sin(yaw)[None]
    u, v = cos * d[..., 0] + sin * d[..., 1], -sin * d[..., 0] + cos * d[..., 1]
    return np.any((np.abs(u) <= half[None, :, 0]) & (np.abs(v) <= half[None, :, 1]), -1)


def test_the_shapes_are_ravens_twenty_in_outline_and_symmetry():
    """Each shape spans its mesh's outline within 3 mm, fits the heightmap's window, and those exactly symmetric
    here cover the same points once turned by their symmetry; Ravens' split and symmetries."""
    assert len(kits.SHAPES) == len(kits.SHAPE_NAMES) == 20
    np.testing.assert_allclose(kits.SYMMETRY, np.asarray(RAVENS_SYMMETRY) * np.pi, atol=1e-6)
    assert tuple(range(14)) == kits.TRAIN_SHAPES and tuple(range(14, 20)) == kits.TEST_SHAPES
    centres, half, yaw = kits.part_table()
    tile = np.asarray(kits.KIT_SIZE[:2]) / np.asarray(kits.TILES)
    assert np.all(np.linalg.norm(2 * half, axis=-1) <= np.linalg.norm(tile))  # the kit's tiles are the largest
    for s, extent in enumerate(RAVENS_EXTENTS):
        parts = half[s, :, 0] > kits.SLIVER
        assert parts.sum() == len(kits.SHAPES[s]) <= kits.MAX_PARTS
        inside = _covered(centres[s, ~parts], centres[s, parts], half[s, parts], yaw[s, parts])
        assert inside.all()  # the slivers hide in the shape
        corners = _corners(centres[s, parts], half[s, parts], yaw[s, parts]).reshape(-1, 2) * 1000
        np.testing.assert_allclose(np.max(np.abs(corners), 0), extent, atol=3.0, err_msg=kits.SHAPE_NAMES[s])
    grid = np.stack(np.meshgrid(*[np.linspace(-0.04, 0.04, 81) + 1.234e-4] * 2, indexing="ij"), -1).reshape(-1, 2)
    for s, turn, symmetric in [(3, np.pi / 2, True), (4, np.pi / 2, True), (6, np.pi, True), (8, np.pi, True),
                               (9, np.pi / 2, True), (11, np.pi / 4, True), (16, np.pi / 3, True),
                               (17, np.pi / 3, True), (0, np.pi, False)]:
        parts = half[s, :, 0] > kits.SLIVER
        box = (centres[s, parts], half[s, parts], yaw[s, parts])
        turned = np.stack([np.cos(turn) * grid[:, 0] - np.sin(turn) * grid[:, 1],
                           np.sin(turn) * grid[:, 0] + np.cos(turn) * grid[:, 1]], -1)
        same = _covered(grid, *box) == _covered(turned, *box)
        assert (same.mean() > 0.999) == symmetric, kits.SHAPE_NAMES[s]


def test_held_out_episodes_are_told_by_their_layout_keys():
    held_out = splits.held_out(100, 20)
    ids = [0, 99, 100, episodes.VAL_BASE, episodes.VAL_BASE + 19, episodes.VAL_BASE + 20, episodes.TRAIN_LOW]
    found = [bool(held_out(splits.layout_key(jnp.asarray(i, jnp.int32)))) for i in ids]
    assert found == [True, True, False, True, True, False, False]
    assert not bool(splits.held_out(3, 0)(splits.layout_key(jnp.asarray(5, jnp.int32))))


@pytest.fixture(scope="module")
def kitted():
    """The arena, the starts of :data:`EPISODES` (their object masks too) and the oracle's actions on the
    :data:`ORACLE` episodes, in one program: per action the reward, success and poses."""
    arena = jarena.build_arena(ARENA)
    oracle = jarena_agents.build_agent("oracle_raven")
    scene = arena.dynamics.init(None, None).scene

    def run(ids):
        start, info = jax.vmap(lambda e: arena.reset(None, episode=e))(ids)
        mask = jax.vmap(lambda p: heightmap.render(scene, p.data.geom_xpos, p.data.geom_xmat, p.geom_size,
                                                   p.geom_rgb).object)(start.physics)
        state, info = jax.tree_util.tree_map(lambda x: x[np.asarray(ORACLE)], (start, info))
        agent = oracle.init(jax.random.key(0), arena.spec, len(ORACLE))

        def one(carry, _):
            state, info, done = carry
            action, _ = oracle.act(agent, info, jax.random.key(0), arena.privileged(state))
            state, info = jax.vmap(arena.step)(state, action)
            out = (jnp.where(done, 0.0, info.reward), info.success, jax.vmap(scoring.planar_poses)(state.physics))
            return (state, info, done | info.terminated | info.truncated), out

        _, steps = jax.lax.scan(one, (state, info, jnp.zeros(len(ORACLE), bool)), None, length=ORACLE_ACTIONS)
        return start, mask, steps

    start, mask, steps = jax.jit(run, compiler_options=FAST_COMPILE)(jnp.asarray(EPISODES))
    host = lambda tree: jax.tree_util.tree_map(np.asarray, tree)  # noqa: E731
    reward, success, planar = host(steps)
    physics = start.physics
    return SimpleNamespace(arena=arena, scene=scene, goal=host(scoring.goal_state(start.task).goal),
                           physics=host(physics), xpos=np.asarray(physics.data.geom_xpos),
                           xmat=np.asarray(physics.data.geom_xmat), mask=np.asarray(mask), reward=reward,
                           success=success, planar=planar,
                           start_planar=host(jax.vmap(scoring.planar_poses)(physics)))


def test_eval_and_val_episodes_draw_unseen_shapes(kitted):
    shapes = kitted.physics.queue.shapes
    held_out = len(EVAL) + len(VAL)
    assert np.all(shapes[:held_out] >= 14) and np.all(shapes[held_out:] < 14)
    for leaf in jax.tree_util.tree_leaves(kitted.physics):
        np.testing.assert_array_equal(leaf[0], leaf[2])  # eval episode 0 twice the same
    assert kitted.arena.max_episode_steps == 10  # Ravens' max_steps


def test_an_episode_lays_out_the_kit_its_slots_and_the_objects(kitted):
    """The kit at rest with its slots at Ravens' offsets, each slot's marks its object's shape turned by the slot's
    heading; the objects at rest on the table, each its shape in its boxes, seen whole (on neither the kit nor
    another object)."""
    scene, goal, physics = kitted.scene, kitted.goal, kitted.physics
    objects = np.asarray(scene.geom)[scene.geom_object < COUNT]
    kit = np.asarray(scene.geom)[scene.geom_object == COUNT]
    marks = kit[kits.KIT_TILES:]
    table = kits.part_table()
    pixels = heightmap.pixel_centres().reshape(-1, 2)
    for i in range(len(EPISODES)):
        planar, shapes = kitted.start_planar[i], physics.queue.shapes[i]
        kit_pose = planar[COUNT]
        assert kit_pose[2] == pytest.approx(0.0025, abs=1e-6)
        np.testing.assert_allclose(planar[:COUNT, 2], 0.01, atol=1e-6)
        cos, sin = np.cos(kit_pose[3]), np.sin(kit_pose[3])
        slots = kit_pose[:2] + np.asarray(kits.SLOT_OFFSETS) @ np.asarray([[cos, sin], [-sin, cos]])
        np.testing.assert_allclose(goal.targets[i, :, :2], slots, atol=1e-5)
        np.testing.assert_allclose(goal.targets[i, :, 2], 0.01)
        np.testing.assert_array_equal(goal.matches[i], shapes[:, None] == shapes[None, :])
        np.testing.assert_allclose(goal.symmetry[i], np.asarray(kits.SYMMETRY)[shapes], atol=1e-6)
        for k in range(COUNT):
            centres, half, yaw = (x[shapes[k]] for x in table)
            mine = slice(k * kits.MAX_PARTS, (k + 1) * kits.MAX_PARTS)
            for pose, geoms, z in ((goal.targets[i, k], marks[mine], kit_pose[2] + kits.MARK_Z),
                                   (planar[k], objects[mine], 0.01)):
                c, s = np.cos(pose[3]), np.sin(pose[3])
                expected = pose[:2] + centres @ np.asarray([[c, s], [-s, c]])
                np.testing.assert_allclose(kitted.xpos[i, geoms, :2], expected, atol=1e-5)
                np.testing.assert_allclose(kitted.xpos[i, geoms, 2], z, atol=1e-5)
                heading = np.arctan2(kitted.xmat[i, geoms, 1, 0], kitted.xmat[i, geoms, 0, 0])
                turn = np.mod(heading - pose[3] - yaw + np.pi, 2 * np.pi) - np.pi
                np.testing.assert_allclose(turn, 0.0, atol=1e-4)
            seen = np.sum(kitted.mask[i] == k)
            parts = half[:, 0] > kits.SLIVER
            c, s = np.cos(planar[k, 3]), np.sin(planar[k, 3])
            world = planar[k, :2] + centres[parts] @ np.asarray([[c, s], [-s, c]])
            area = np.sum(_covered(pixels, world, half[parts], yaw[parts] + planar[k, 3]))
            assert seen == area > 0, (i, k)
        kit_area = np.prod(kits.KIT_SIZE[:2]) / heightmap.PIXEL_SIZE ** 2
        assert abs(np.sum(kitted.mask[i] == COUNT) - kit_area) < 0.01 * kit_area + 40


def _goal(shapes, targets):
    """The task's goal for objects of ``shapes`` (5,) and slots at ``targets`` (5, 4)."""
    queue = kits.Kitting(shapes=jnp.asarray(shapes, jnp.int32), targets=jnp.asarray(targets, jnp.float32))
    return tasks.assembling_kits().goal(SimpleNamespace(queue=queue))


def test_objects_score_in_a_slot_of_their_shape_modulo_its_symmetry():
    """A circle, a square, two Rs and a hexagon; each object in a slot of its shape within 1 cm and 15 degrees,
    modulo its symmetry, scores 1/5 (two Rs in one R slot both count, as in Ravens)."""
    shapes = [11, 3, 0, 0, 17]
    targets = np.asarray([[0.4 + 0.1 * k, 0.1 * k - 0.2, 0.01, 0.3 * k] for k in range(COUNT)], np.float32)
    goal = _goal(shapes, targets)
    far = np.asarray([[0.4 + 0.1 * k, 0.4, 0.01, 0.0] for k in range(COUNT)], np.float32)

    def placed(**moves):
        planar = far.copy()
        for name, (slot, dx, turn) in moves.items():
            k = int(name[1:])
            planar[k] = targets[slot] + np.asarray([dx, 0.0, 0.0, turn], np.float32)
        return planar

    degree = np.pi / 180
    cases = {
        "none placed": (placed(), 0),
        "all in their slots": (placed(**{f"o{k}": (k, 0.0, 0.0) for k in range(COUNT)}), 5),
        "circle turned any way": (placed(o0=(0, 0.0, 1.0)), 1),
        "square a quarter turn": (placed(o1=(1, 0.0, np.pi / 2)), 1),
        "square an eighth of a turn": (placed(o1=(1, 0.0, np.pi / 4)), 0),
        "R turned 14 degrees": (placed(o2=(2, 0.0, 14 * degree)), 1),
        "R turned 16 degrees": (placed(o2=(2, 0.0, 16 * degree)), 0),
        "R turned half a turn": (placed(o2=(2, 0.0, np.pi)), 0),
        "R in the other R slot": (placed(o2=(3, 0.0, 0.0)), 1),
        "both Rs in one slot": (placed(o2=(3, 0.0, 0.0), o3=(3, 0.0, 0.0)), 2),
        "R in the square's slot": (placed(o2=(1, 0.0, 0.0)), 0),
        "hexagon a sixth of a turn, 9 mm off": (placed(o4=(4, 0.009, np.pi / 3)), 1),
        "hexagon 11 mm off": (placed(o4=(4, 0.011, 0.0)), 0),
    }
    params = scoring.PoseGoalParams()
    score = jax.jit(jax.vmap(lambda planar: scoring.score(planar, goal, params)))
    values = np.asarray(score(jnp.asarray(np.stack([planar for planar, _ in cases.values()]))))
    for (name, (_, expected)), value in zip(cases.items(), values, strict=True):
        assert value == pytest.approx(expected / COUNT, abs=1e-6), name


def test_the_oracle_puts_every_object_in_a_slot_of_its_shape(kitted):
    """One object an action, 1/5 each; the fifth completes the kit: success, and the episode ends. The objects
    rest in their slots within 1 mm and a degree, modulo their symmetry."""
    for i, e in enumerate(ORACLE):
        np.testing.assert_allclose(kitted.reward[:, i], 1 / COUNT, atol=1e-5)
        assert kitted.success[-1, i] and not kitted.success[:-1, i].any()
        final, goal = kitted.planar[-1, i, :COUNT], jax.tree_util.tree_map(lambda x, e=e: x[e], kitted.goal)
        distance = np.linalg.norm(final[:, None, :2] - goal.targets[None, :, :2], axis=-1)
        distance = np.where(goal.matches, distance, np.inf)
        slot = np.argmin(distance, -1)
        assert np.all(np.min(distance, -1) < 1e-3), distance
        turn = np.asarray(scoring.heading_error(final[:, 3], goal.targets[slot, 3], goal.symmetry))
        assert np.all(turn < np.deg2rad(1.0)), turn
        np.testing.assert_allclose(final[:, 2], 0.01, atol=1e-3)  # on the table
        np.testing.assert_array_equal(np.sort(slot), np.arange(COUNT))  # a slot each


def test_the_scene_keeps_few_contacts():
    """Objects collide with the table and each other; the kit and its marks are only seen. MJX's broad phase
    keeps the 16 nearest pairs of boxes of different objects (of 5 x 4 / 2 x 36) and every box's table pair."""
    import mujoco

    state = jarena.build_arena(ARENA).dynamics.init(None, None)
    scene, model = state.scene, state.scene.model
    assert int(model.numeric_data[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "max_geom_pairs")]) == 16
    geoms = np.asarray(scene.geom)
    kit, objects = geoms[scene.geom_object == COUNT], geoms[scene.geom_object < COUNT]
    assert len(kit) == kits.KIT_TILES + COUNT * kits.MAX_PARTS and len(objects) == COUNT * kits.MAX_PARTS
    assert not np.any(model.geom_contype[kit] | model.geom_conaffinity[kit])
    assert np.all(model.geom_contype[objects] & model.geom_conaffinity[objects])
    assert state.data._impl.ncon == (16 + COUNT * kits.MAX_PARTS) * 4
