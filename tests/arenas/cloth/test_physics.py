"""Cloth physics with known answers: free fall, a drape, a cloth at rest, the floor, a fold, a grasp."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas.cloth import collision, coverage
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import ClothPhysics

MESH = ClothMesh.of_size(0.3, 0.3, cols=16)


def _run(physics, params, state, controls):
    return jax.jit(lambda s, c: jax.lax.scan(lambda s, c: (physics.step(s, c, params), None), s, c)[0])(state,
                                                                                                       controls)


def _still(physics, steps, grip=-1.0):
    return jnp.tile(jnp.array([0.0, 0.0, 0.0, grip]), (steps, physics.num_pickers, 1))


def _edge_strain(positions, mesh):
    g = np.asarray(positions).reshape(mesh.rows, mesh.cols, 3)
    edges = np.concatenate([np.linalg.norm(g[:, 1:] - g[:, :-1], axis=-1).ravel(),
                            np.linalg.norm(g[1:] - g[:-1], axis=-1).ravel()])
    return edges / mesh.spacing - 1.0


def test_free_fall_follows_half_g_t_squared():
    physics = ClothPhysics(MESH)
    params = physics.default_params().replace(damping=jnp.float32(0.0))
    state = physics.state_from_positions(MESH.rest_positions + np.array([0, 0, 1.0], np.float32))
    state = _run(physics, params, state, _still(physics, 30))
    t = 30 * physics.dt
    drop = 1.0 - np.asarray(state.positions[:, 2])
    np.testing.assert_allclose(drop, 0.5 * 9.81 * t**2, rtol=0.01)  # semi-implicit Euler: within 1%
    np.testing.assert_allclose(np.asarray(state.velocities[:, 2]), -9.81 * t, rtol=1e-3)
    assert abs(float(np.abs(_edge_strain(state.positions, MESH)).max())) < 1e-4  # falls without deforming


def test_a_cloth_held_at_two_corners_drapes_without_stretching():
    physics = ClothPhysics(MESH, num_pickers=2)
    params = physics.default_params()
    rest = MESH.rest_positions + np.array([0, 0, 0.5], np.float32)
    state = physics.state_from_positions(rest).replace(picker_positions=jnp.asarray(rest[MESH.corners[:2]]))
    state = _run(physics, params, state, _still(physics, 600, grip=1.0))
    assert float(jnp.abs(state.velocities).max()) < 0.05  # static
    strain = _edge_strain(state.positions, MESH)
    g = np.asarray(state.positions).reshape(MESH.rows, MESH.cols, 3)
    length = np.linalg.norm(np.diff(g, axis=0), axis=-1).sum(axis=0) / MESH.height  # each column, top to bottom
    assert np.all(np.abs(length - 1) < 0.02), length  # stretch under 2% along the hanging direction
    assert np.abs(strain).mean() < 0.01 and strain.max() < 0.06
    assert float(g[-1, :, 2].mean()) < 0.5 - 0.9 * MESH.height  # it hangs
    np.testing.assert_allclose(np.asarray(state.positions[MESH.corners[:2]]), rest[MESH.corners[:2]], atol=1e-6)


def test_a_flat_cloth_at_rest_stays_put_on_the_floor():
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    start = MESH.rest_positions + np.array([0, 0, 1.0], np.float32) * float(params.particle_radius)
    state = physics.state_from_positions(start)
    covered = jax.jit(lambda x: coverage.coverage(x, MESH))  # one program for both, not a hundred eager ops
    before = float(covered(state.positions))
    state = _run(physics, params, state, _still(physics, 1000))
    after = float(covered(state.positions))
    assert abs(after / before - 1) < 0.005
    assert float(state.positions[:, 2].min()) >= float(params.particle_radius) - 1e-5
    np.testing.assert_allclose(np.asarray(state.positions[:, :2]), start[:, :2], atol=1e-3)


def test_no_particle_goes_below_the_floor_when_dropped():
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    tilted = MESH.rest_positions.copy()
    tilted[:, 2] = 0.2 + 0.5 * tilted[:, 0]  # a slanted cloth falls, one edge first
    state = _run(physics, params, physics.state_from_positions(tilted), _still(physics, 150))
    assert float(state.positions[:, 2].min()) >= float(params.particle_radius) - 1e-4
    assert float(jnp.abs(state.velocities).max()) < 0.1


def _two_layers(physics, params, mesh):
    """Half the cloth folded over onto the other half, 2 cm above it, dropped and left to settle for 1 s."""
    x = mesh.rest_positions.copy() + np.array([0, 0, 1.0], np.float32) * float(params.particle_radius)
    rows = np.arange(mesh.num_particles) // mesh.cols
    upper = rows < mesh.rows // 2
    x[upper, 1] = -x[upper, 1]  # mirrored about the middle row: a fold along y = 0
    x[upper, 2] += 0.02 + 0.01 * (x[upper, 1] / x[upper, 1].max())  # the folded half falls from 2-3 cm
    return _run(physics, params, physics.state_from_positions(x), _still(physics, 100)), upper


def test_a_folded_cloth_keeps_its_two_layers_apart():
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    state, upper = _two_layers(physics, params, MESH)
    x = np.asarray(state.positions)
    rows = np.arange(MESH.num_particles) // MESH.cols
    top, bottom = x[rows < MESH.rows // 2 - 1], x[rows > MESH.rows // 2]
    d = np.linalg.norm(top[:, None] - bottom[None], axis=-1)
    assert d.min() >= 0.97 * float(params.self_collision_distance), d.min()
    assert np.median(top[:, 2]) > np.median(bottom[:, 2]) + 0.5 * float(params.self_collision_distance)
    assert float(jnp.abs(state.velocities).max()) < 0.05
    covered = jax.jit(lambda x: coverage.normalised_coverage(x, MESH))(state.positions)  # one program, not 100
    assert 0.45 < float(covered) < 0.6  # about half the area


def test_without_self_collision_the_layers_pass_through(monkeypatch):
    """The check above would catch a cloth whose layers interpenetrate."""
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    monkeypatch.setattr(collision, "separate", lambda x, *args: x)
    x = np.asarray(_two_layers(physics, params, MESH)[0].positions)
    rows = np.arange(MESH.num_particles) // MESH.cols
    top, bottom = x[rows < MESH.rows // 2 - 1], x[rows > MESH.rows // 2]
    assert np.linalg.norm(top[:, None] - bottom[None], axis=-1).min() < 0.5 * float(params.self_collision_distance)


def test_pickers_grasp_the_top_layer_and_release():
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    state = physics.state_from_positions(MESH.rest_positions + np.array([0, 0, 0.004], np.float32))
    centre = MESH.index(MESH.rows // 2, MESH.cols // 2)
    target = np.asarray(state.positions[centre])
    state = state.replace(picker_positions=jnp.asarray(target)[None])
    step = jax.jit(physics.step)  # one program for the grasp and the release (op by op: hundreds of small ones)
    state = step(state, jnp.array([[0.0, 0.0, 0.0, 1.0]]), params)
    held = np.asarray(state.held[0])
    held = held[held >= 0]
    d = np.linalg.norm(MESH.rest_positions[held, :2] - MESH.rest_positions[centre, :2], axis=-1)
    assert centre in held and d.max() <= float(params.grasp_radius)
    assert len(held) == int(np.sum(np.linalg.norm(MESH.rest_positions[:, :2] - MESH.rest_positions[centre, :2],
                                                  axis=-1) <= float(params.grasp_radius)))
    lift = jnp.tile(jnp.array([0.0, 0.0, 0.01, 1.0]), (10, 1, 1))
    state = _run(physics, params, state, lift)
    np.testing.assert_allclose(float(state.positions[centre, 2]), target[2] + 0.1, atol=1e-5)
    state = step(state, jnp.array([[0.0, 0.0, 0.0, -1.0]]), params)
    assert not bool(state.grasped.any())
    state = _run(physics, params, state, _still(physics, 100))
    assert float(state.positions[centre, 2]) < 0.02  # fell back down


def test_a_picker_above_the_cloth_grasps_nothing():
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    state = physics.state_from_positions(MESH.rest_positions)  # pickers at the ready pose, 0.3 m up
    state = jax.jit(physics.step)(state, jnp.array([[0.0, 0.0, 0.0, 1.0]]), params)  # one program, not hundreds
    assert not bool(state.grasped.any())


@pytest.mark.parametrize("batch", [1, 3])
def test_steps_are_deterministic_and_batch_independent(batch):
    physics = ClothPhysics(MESH)
    params = physics.default_params()
    noise = jax.random.normal(jax.random.key(1), (MESH.num_particles, 3)) * 0.01
    state = physics.state_from_positions(MESH.rest_positions + jnp.array([0, 0, 0.05]) + noise)
    one = jax.jit(physics.step)(state, jnp.zeros((1, 4)), params)
    states = jax.tree_util.tree_map(lambda x: jnp.stack([x] * batch), state)
    step_many = jax.jit(jax.vmap(physics.step, in_axes=(0, None, None)))
    many, again = step_many(states, jnp.zeros((1, 4)), params), step_many(states, jnp.zeros((1, 4)), params)
    np.testing.assert_array_equal(np.asarray(many.positions), np.asarray(again.positions))
    for i in range(batch):  # XLA on the CPU may round the last bit differently for another batch size
        np.testing.assert_allclose(np.asarray(many.positions[i]), np.asarray(one.positions), atol=1e-6)


def test_the_neighbour_list_finds_the_close_pairs_all_pairs_would():
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.uniform(0, 0.1, (300, 3)).astype(np.float32))
    radius = 0.02
    never = lambda i, j: jnp.zeros(i.shape, bool)  # noqa: E731
    found, overflow = jax.jit(lambda x: collision.neighbour_list(x, radius, never, max_neighbours=64))(x)
    found = np.asarray(found)
    assert int(overflow) == 0
    d = np.linalg.norm(np.asarray(x)[:, None] - np.asarray(x)[None], axis=-1)
    for i in range(300):
        expect = set(np.nonzero((d[i] < radius) & (np.arange(300) != i))[0])
        assert set(found[i][found[i] >= 0]) == expect


def test_the_neighbour_list_counts_the_particles_it_could_not_read():
    x = jnp.full((20, 3), 0.005, jnp.float32).at[:, 0].add(jnp.arange(20) * 1e-4)  # 20 in one cell
    never = lambda i, j: jnp.zeros(i.shape, bool)  # noqa: E731
    _, overflow = jax.jit(lambda x: collision.neighbour_list(x, 0.02, never, candidates=16))(x)
    assert int(overflow) == 20 * (20 - 16)  # each of the 20 misses 4


def test_the_pairwise_search_lists_the_same_pairs_in_the_same_order_and_the_same_overflow():
    # the jax.numpy solver's list for small cloths: equal to neighbour_list's, in the slots' order (the pushes
    # are summed in it), also where the candidate slots run out or a particle keeps only its nearest pairs
    rng = np.random.default_rng(2)
    adjacent = lambda i, j: (jnp.abs(i // 10 - j // 10) <= 1) & (jnp.abs(i % 10 - j % 10) <= 1)  # noqa: E731
    piles = rng.uniform(-0.2, 0.2, (3, 3))[rng.integers(0, 3, 200)] + rng.normal(0, 0.01, (200, 3))
    spread = rng.uniform(-0.3, 0.3, (200, 3)) * np.array([1, 1, 0.1])
    overflows = []
    for x, radius, candidates, kept in [(piles, 0.02, 48, 16), (piles, 0.03, 192, 4), (spread, 0.05, 16, 16),
                                        (spread, 0.06, 192, 16)]:
        x = jnp.asarray(x, jnp.float32)
        search = jax.jit(lambda x, f: f(x, jnp.float32(radius), adjacent, candidates=candidates,
                                        max_neighbours=kept), static_argnums=1)
        (expect, overflow), (found, counted) = search(x, collision.neighbour_list), search(
            x, collision.neighbour_list_pairwise)
        np.testing.assert_array_equal(np.asarray(found), np.asarray(expect))
        assert int(counted) == int(overflow)
        overflows.append(int(overflow))
    assert all(overflows[:3]) and (np.asarray(expect) >= 0).sum() > 200, overflows


def test_self_collision_pushes_are_equal_and_opposite():
    # a particle pressed into a layer of six: the correction moves the pile's centre of mass by nothing,
    # however many contacts a particle has (an unequal push would make a resting pile crawl)
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 0.01, (40, 3)).astype(np.float32)
    never = lambda i, j: jnp.zeros(i.shape, bool)  # noqa: E731

    @jax.jit  # one program (op by op, the list and the pushes dispatch over a hundred small ones)
    def separated(x):
        neighbours, _ = collision.neighbour_list(x, 0.01, never, max_neighbours=40)
        share = collision.pair_shares(jnp.ones((40,), jnp.float32), neighbours)
        xs = collision.components(x)
        return collision.separate(xs, xs, share, neighbours, jnp.float32(0.005), jnp.float32(0.3))

    moved = np.stack([np.asarray(o) for o in separated(jnp.asarray(x))], -1) - x
    assert np.abs(moved).max() > 1e-4  # pairs were pushed
    np.testing.assert_allclose(moved.sum(0), 0.0, atol=1e-6)


def test_a_crumpled_cloth_left_alone_comes_to_rest_where_it_lies():
    # a 16-pixel camera: each step renders the observation, which this test of the physics does not read
    arena = jarena.build_arena("cloth|domain:square_fabric,initial:crumpled,particles:24,action:picker,"
                               "eval_episodes:4,resolution:16")
    states, _ = jax.jit(jax.vmap(lambda e: arena.reset(episode=e)))(jnp.asarray(list(arena.episodes("eval"))))
    still = jnp.zeros((4,) + arena.action_spec.shape)
    later = jax.jit(lambda s: jax.lax.fori_loop(0, 100, lambda _, s: jax.vmap(arena.step)(s, still)[0], s))(states)
    start, end = np.asarray(states.physics.positions), np.asarray(later.physics.positions)
    drift = np.linalg.norm(end.mean(1)[:, :2] - start.mean(1)[:, :2], axis=-1)
    speed = np.linalg.norm(np.asarray(later.physics.velocities), axis=-1).mean(1)
    assert drift.max() < 0.01, drift  # metres in 1 s
    assert speed.max() < 0.05, speed  # m/s
    assert np.asarray(later.physics.collision_overflow).max() == 0


def test_each_particle_is_tethered_to_the_nearest_held_particle_on_the_flat_cloth_first_of_equals():
    mesh = ClothMesh(rows=6, cols=7, spacing=0.02)
    physics = ClothPhysics(mesh, num_pickers=2, max_held=5)
    # picker 0 holds two particles equally far from many others (ties go to the first slot) and empty slots;
    # picker 1 holds none
    held = jnp.array([[-1, mesh.index(1, 1), -1, mesh.index(1, 5), mesh.index(4, 3)], [-1] * 5], jnp.int32)
    to, length = physics._tethers(held)
    rows, cols = np.divmod(np.arange(mesh.num_particles), mesh.cols)
    for p in range(mesh.num_particles):
        slots = [g for g in range(5) if held[0, g] >= 0]
        rest = [np.hypot(rows[p] - rows[held[0, g]], cols[p] - cols[held[0, g]]) * mesh.spacing for g in slots]
        best = slots[int(np.argmin(rest))]
        assert int(to[p, 0]) == int(held[0, best])
        np.testing.assert_allclose(float(length[p, 0]), min(rest), rtol=1e-6)
    assert (np.asarray(to[:, 1]) == -1).all() and np.isinf(np.asarray(length[:, 1])).all()
    assert int(to[mesh.index(1, 3), 0]) == int(held[0, 1])  # equally far from (1, 1) and (1, 5): the first slot
