"""Raven's packing-boxes: the kd-split against Ravens' rule, the layout, the zone score and the oracle.

One compiled program (XLA's quick options) resets eval episodes 0, 0 and 1 and runs the oracle on the last two
for 4 actions, then one scripted action that puts box 0 on box 1; the split and the zone scores of hand-placed
boxes are compiled without the physics step.
"""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.raven import heightmap, packing, poses, scoring
from tests.arenas.raven import FAST_COMPILE

ARENA = "raven|task:packing-boxes"
SLOTS = packing.MAX_BOXES
EPISODES = (0, 0, 1)  # 2, 2 and 4 boxes; the oracle runs the last two
ORACLE_ACTIONS = 4


def _ravens_split(rng, inside):
    """Ravens' kd-tree rule in numpy (the reference): the boxes ``(lo, hi)`` (B, 2) each, relative to the inside's
    centre, depth first."""
    boxes = []

    def cut(lo, hi):
        size = hi - lo
        can = size > 2 * 0.05
        if not can.any():
            boxes.append((lo, hi))
            return
        axis = rng.choice(2, p=can / can.sum())
        at = rng.random() * (size[axis] - 0.1) + lo[axis] + 0.05
        first_hi, second_lo = hi.copy(), lo.copy()
        first_hi[axis], second_lo[axis] = at - 0.005, at + 0.005
        cut(lo, first_hi)
        cut(second_lo, hi)

    cut(-inside / 2, inside / 2)
    return np.asarray([b[0] for b in boxes]), np.asarray([b[1] for b in boxes])


def _check_split(inside, centres, sizes, present, capacity):
    """Ravens' invariants of one split: the boxes lie in the inside, 1 cm apart at least along one axis, cover it
    but for the gaps of the cuts, and each side is the inside's (never cut) or 4.5 to 10 cm."""
    count = int(present.sum())
    assert 1 <= count <= capacity and present[:count].all() and not present[count:].any()
    c, s = centres[:count], sizes[:count]
    lo, hi = c - s / 2, c + s / 2
    eps = 1e-5
    assert np.all(lo >= -inside / 2 - eps) and np.all(hi <= inside / 2 + eps)
    np.testing.assert_allclose(lo[0], -inside / 2, atol=eps)  # the first half of every cut first: the low corner
    gap = np.maximum(lo[:, None] - hi[None], lo[None] - hi[:, None])  # (B, B, 2)
    apart = np.max(gap, -1) >= packing.MARGIN - eps
    assert np.all(apart | np.eye(count, dtype=bool))
    grid = np.stack(np.meshgrid(*(np.linspace(-i / 2, i / 2, 15) for i in inside), indexing="ij"), -1).reshape(-1, 2)
    near = np.all(np.abs(grid[:, None] - c[None]) <= s[None] / 2 + packing.MARGIN / 2 + eps, -1)
    assert near.any(-1).all()  # every point of the inside is in a box or a cut's gap
    whole = np.abs(s - inside) < eps
    assert np.all(whole | (s >= packing.MIN_OBJECT_DIM - packing.MARGIN / 2 - eps))
    if count < capacity:  # nothing left to cut
        assert np.all(s <= 2 * packing.MIN_OBJECT_DIM + eps)


def test_the_kd_split_cuts_the_container_as_ravens_does():
    count = 2000
    insides = np.random.default_rng(1).uniform(0.03, 0.28, (count, 2)).astype(np.float32)
    keys = jax.random.split(jax.random.key(0), count)
    split = jax.jit(jax.vmap(packing.kd_split, in_axes=(0, 0, None)), static_argnums=2)
    centres, sizes, present = (np.asarray(x) for x in split(keys, insides, SLOTS))
    for i in range(count):
        _check_split(insides[i], centres[i], sizes[i], present[i], SLOTS)
    # the same law as Ravens' rule: the number of boxes and their sizes
    rng = np.random.default_rng(2)
    reference = [_ravens_split(rng, inside.astype(np.float64)) for inside in insides]
    counts, ravens_counts = present.sum(-1), np.asarray([len(lo) for lo, _ in reference])
    assert counts.mean() == pytest.approx(ravens_counts.mean(), abs=0.15)
    for k in (1, 2, 4):
        assert np.mean(counts == k) == pytest.approx(np.mean(ravens_counts == k), abs=0.03), k
    sides = sizes[present]
    ravens_sides = np.concatenate([hi - lo for lo, hi in reference])
    assert sides.mean() == pytest.approx(ravens_sides.mean(), abs=0.0015)
    assert sides.min() >= 0.03 - 1e-6 and sides.max() <= 0.1 + 1e-6
    # a capacity stops the cutting: the parts left whole still tile the inside
    small = split(keys[:50], np.full((50, 2), 0.28, np.float32), 4)
    for i in range(50):
        _check_split(np.full(2, 0.28, np.float32), *(np.asarray(x[i]) for x in small), 4)


def test_box_points_are_ravens_grid():
    """A 2 cm grid from -size / 2, short of size / 2: 3 x 5 x 3 points on a 6 x 10 x 5 cm box, 2 x 3 x 3 on 3.2 x
    4.6 x 5 cm."""
    sizes = np.asarray([[0.06, 0.1, 0.05], [0.032, 0.046, 0.05], [0.1, 0.1, 0.05]], np.float32)
    points, valid = (np.asarray(x) for x in packing.points_grid(sizes))
    assert valid.sum(-1).tolist() == [45, 18, 75]
    for box, size in enumerate(sizes):
        grid = np.stack(np.meshgrid(*(np.arange(-s / 2, s / 2, 0.02) for s in size), indexing="ij"), -1)
        np.testing.assert_allclose(np.sort(points[box][valid[box]], 0), np.sort(grid.reshape(-1, 3), 0), atol=1e-6)


def _put(state, box, onto):
    """An action that picks ``box`` at its centre and puts it on ``onto``'s centre, unturned."""
    planar = scoring.planar_poses(state.physics)
    return jnp.concatenate([heightmap.world_to_pixel(planar[box, :2]), heightmap.world_to_pixel(planar[onto, :2]),
                            jnp.zeros(1)])


@pytest.fixture(scope="module")
def packed():
    """The arena, the starts of :data:`EPISODES` (their object masks too), and the oracle's actions then
    :func:`_put` of box 0 on box 1 in all but the first, in one program: per action the reward, termination,
    success and poses."""
    arena = jarena.build_arena(ARENA)
    oracle = jarena_agents.build_agent("oracle_raven")
    scene = arena.dynamics.init(None, None).scene

    def run(episodes):
        state, info = jax.vmap(lambda e: arena.reset(None, episode=e))(episodes)
        start = state
        mask = jax.vmap(lambda p: heightmap.render(scene, p.data.geom_xpos, p.data.geom_xmat, p.geom_size,
                                                   p.geom_rgb).object)(state.physics)
        state, info = jax.tree_util.tree_map(lambda x: x[1:], (state, info))
        agent = oracle.init(jax.random.key(0), arena.spec, len(EPISODES) - 1)

        def one(carry, k):
            state, info, done = carry
            action, _ = oracle.act(agent, info, jax.random.key(0), arena.privileged(state))
            action = jnp.where(k == ORACLE_ACTIONS, jax.vmap(lambda s: _put(s, 0, 1))(state), action)
            state, info = jax.vmap(arena.step)(state, action)
            out = (jnp.where(done, 0.0, info.reward), info.terminated, info.success,
                   jax.vmap(scoring.planar_poses)(state.physics))
            return (state, info, done | info.terminated | info.truncated), out

        _, steps = jax.lax.scan(one, (state, info, jnp.zeros(len(EPISODES) - 1, bool)),
                                jnp.arange(ORACLE_ACTIONS + 1))
        return start, info, mask, steps

    start, info, mask, steps = jax.jit(run, compiler_options=FAST_COMPILE)(jnp.asarray(EPISODES))
    host = lambda tree: jax.tree_util.tree_map(np.asarray, tree)  # noqa: E731
    reward, terminated, success, planar = host(steps)
    return SimpleNamespace(arena=arena, start=start, goal=host(scoring.goal_state(start.task).goal),
                           physics=host(start.physics), placed=np.asarray(info.metrics["placed"]), mask=host(mask),
                           reward=reward, terminated=terminated, success=success, planar=planar,
                           start_planar=host(jax.vmap(scoring.planar_poses)(start.physics)))


def test_an_episode_lays_out_the_container_and_spawns_its_boxes_apart(packed):
    assert packed.arena.max_episode_steps == 20  # Ravens' max_steps
    goal, physics, planar = packed.goal, packed.physics, packed.start_planar
    for leaf in jax.tree_util.tree_leaves(physics):
        np.testing.assert_array_equal(leaf[0], leaf[1])  # episode 0 twice the same
    counts = goal.present.sum(-1)
    assert counts.tolist() == [2, 2, 4] and packed.placed.tolist() == [0.0] * 2
    box_geoms = np.flatnonzero(packed.start.physics.scene.geom_object < SLOTS)
    for i in range(len(EPISODES)):
        size, count = physics.queue.size[i], counts[i]
        assert np.all(size[:2] >= 0.05) and np.all(size[:2] <= 0.3) and size[2] == pytest.approx(0.05)
        container = planar[i, SLOTS]
        np.testing.assert_allclose(goal.zone.pose[i], container)
        np.testing.assert_allclose(goal.zone.size[i], size[:2])
        assert container[2] == pytest.approx(0.025)
        extents = 2 * physics.geom_size[i, box_geoms[:count]]
        np.testing.assert_allclose(extents[:, 2], 0.05, atol=1e-6)
        assert np.all(planar[i, count:SLOTS, 0] > 1.5)  # unused slots parked
        np.testing.assert_allclose(planar[i, :count, 2], 0.025, atol=1e-6)  # on the table
        # the targets: the split's boxes inside the container, 1 cm within its edges, in its heading
        local = poses.rotate(poses.yaw_quat(-container[3]), np.concatenate(
            [goal.targets[i, :count, :2] - container[:2], np.zeros((count, 1))], -1))
        assert np.all(np.abs(np.asarray(local)[:, :2]) + extents[:, :2] / 2 <= size[:2] / 2 - 0.01 + 1e-5)
        np.testing.assert_allclose(goal.targets[i, :count, 2], 0.05, atol=1e-6)
        turn = goal.targets[i, :count, 3] - container[3]
        np.testing.assert_allclose(np.mod(turn + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-5)
        # seen from above, every box whole (none on the container or another box), the container whole too
        pixels = np.bincount(packed.mask[i].reshape(-1) + 1, minlength=SLOTS + 2)[1:]
        area = np.prod(extents[:, :2], -1) / heightmap.PIXEL_SIZE ** 2
        assert np.all(np.abs(pixels[:count] - area) < 0.1 * area + 40), (pixels[:count], area)
        outer = np.prod(size[:2] + packing.WALL) / heightmap.PIXEL_SIZE ** 2
        assert abs(pixels[SLOTS] - outer) < 0.05 * outer + 60
        colours = physics.geom_rgb[i, box_geoms[:count]]
        assert all(any(np.allclose(c, b, atol=1e-6) for b in packing.BOX_COLOURS) for c in colours)


def test_the_oracle_packs_every_box_where_the_split_cut_it(packed):
    """A box an action, farthest first, each worth its share of all the boxes' points; the last one completes
    the packing: success, and the episode ends."""
    goal, counts = packed.goal, packed.goal.present.sum(-1)
    valid = goal.zone.valid.sum(-1)  # points a box
    for i, e in enumerate(range(1, len(EPISODES))):  # rollout i of start e
        count = counts[e]
        moved = np.linalg.norm(packed.planar[:count, i, :count, :2] - np.concatenate(
            [packed.start_planar[None, e, :count, :2], packed.planar[:count - 1, i, :count, :2]]), axis=-1) > 1e-3
        assert np.all(moved.sum(-1) == 1), moved  # one box an action
        placed = np.argmax(moved, -1)
        np.testing.assert_allclose(packed.reward[:count, i], valid[e, placed] / valid[e, :count].sum(), atol=1e-5)
        assert packed.reward[:ORACLE_ACTIONS, i].sum() == pytest.approx(1.0, abs=1e-5)
        assert packed.success[count - 1, i] and packed.terminated[count - 1, i]
        assert not packed.success[:count - 1, i].any()
        final = packed.planar[ORACLE_ACTIONS - 1, i, :count]
        np.testing.assert_allclose(final[:, :2], goal.targets[e, :count, :2], atol=1e-3)
        turn = final[:, 3] - goal.targets[e, :count, 3]
        np.testing.assert_allclose(np.mod(turn + np.pi, 2 * np.pi) - np.pi, 0.0, atol=np.deg2rad(1.0))
        np.testing.assert_allclose(final[:, 2], 0.025, atol=1e-3)  # on the table, in the container


def test_a_box_put_on_another_rests_on_it_and_still_counts(packed):
    """Boxes collide with each other (the broad phase keeps the near pairs): box 0 put on box 1's centre rests on
    it, 5 cm up, and all its points are still in the container (Ravens' zone ignores heights under 0.3 m)."""
    for i in range(len(EPISODES) - 1):
        before, after = packed.planar[ORACLE_ACTIONS - 1, i], packed.planar[ORACLE_ACTIONS, i]
        np.testing.assert_allclose(after[0, :2], before[1, :2], atol=2e-3)
        assert after[0, 2] == pytest.approx(0.075, abs=2e-3)
        assert packed.reward[ORACLE_ACTIONS, i] == pytest.approx(0.0, abs=1e-6)


def test_the_zone_scores_the_share_of_box_points_in_the_container(packed):
    """Hand-placed boxes of eval episode 1 (4 boxes), every box's points Ravens' grid, all counted together."""
    goal = jax.tree_util.tree_map(lambda x: x[2], packed.goal)
    start = packed.start_planar[2]
    container, size = start[SLOTS], packed.physics.queue.size[2]
    valid = goal.zone.valid.sum(-1)[:4]
    total = valid.sum()
    extents = 2 * packed.physics.geom_size[2, :4]
    params = scoring.PoseGoalParams()

    def placed(*boxes):
        planar = start.copy()
        for box, pose in boxes:
            planar[box] = pose
        return planar

    def in_container(x, y, z=0.025, turn=0.0):
        """A planar pose at (x, y) in the container's frame."""
        cos, sin = np.cos(container[3]), np.sin(container[3])
        return (container[0] + cos * x - sin * y, container[1] + sin * x + cos * y, z, container[3] + turn)

    # box 0 centred on the container's +x edge: its points short of the edge (x offsets under half its size)
    offsets = np.arange(-extents[0, 0] / 2, extents[0, 0] / 2, 0.02)
    short = np.sum(offsets < 0) * valid[0] // len(offsets)
    cases = {
        "at the start": (start, 0.0),
        "box 0 at its place": (placed((0, goal.targets[0])), valid[0] / total),
        "every box at its place": (placed(*((b, goal.targets[b]) for b in range(4))), 1.0),
        "box 0 in the middle, turned": (placed((0, in_container(0.0, 0.0, turn=0.3))), valid[0] / total),
        "box 0 on the +x edge": (placed((0, in_container(size[0] / 2, 0.0))), short / total),
        "box 0 held 0.34 m up: 1 of 3 rows under 0.3 m": (placed((0, in_container(0.0, 0.0, 0.34))),
                                                          valid[0] / 3 / total),
        "box 0 beside the container": (placed((0, in_container(size[0] / 2 + 0.06, 0.0))), 0.0),
    }
    score = jax.jit(jax.vmap(lambda planar: scoring.score(planar, goal, params)))
    values = np.asarray(score(jnp.asarray(np.stack([planar for planar, _ in cases.values()]), jnp.float32)))
    for (name, (_, expected)), value in zip(cases.items(), values, strict=True):
        assert value == pytest.approx(expected, abs=1e-6), name


def test_the_scene_keeps_the_nearest_pairs_of_boxes():
    """Boxes collide with the table, the container's wall pieces and each other; MJX's broad phase keeps the 32
    nearest pairs of boxes of 430 (20 x 19 / 2 boxes with boxes, 20 x 12 with wall pieces) and every box's table
    pair: (32 + 20) x 4 contact slots."""
    import mujoco

    scene = jarena.build_arena(ARENA).dynamics.init(None, None).scene
    model = scene.model
    assert int(model.numeric_data[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "max_geom_pairs")]) == 32
    container = np.asarray(scene.geom)[scene.geom_object == SLOTS]
    boxes = np.asarray(scene.geom)[scene.geom_object < SLOTS]
    assert len(container) == 21 and len(boxes) == SLOTS
    solid = model.geom_contype[container] | model.geom_conaffinity[container]
    assert solid.tolist() == [0] * 9 + [1] * 12  # the floor's tiles only seen
    assert np.all(model.geom_contype[boxes] & model.geom_conaffinity[boxes])
    state = jarena.build_arena(ARENA).dynamics.init(None, None)
    assert state.data._impl.ncon == (32 + SLOTS) * 4
