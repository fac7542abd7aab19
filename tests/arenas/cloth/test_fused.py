"""The fused substep kernel (Pallas; interpreted on the CPU) against the jax.numpy solver on the same states."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.cloth import collision, fused
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import ClothPhysics, _constraint_pairs, neighbours_xla

MESH = ClothMesh(rows=7, cols=9, spacing=0.02)  # rectangular, and 63 particles pad to 64


def _crumpled(physics, key):
    """A cloth dropped in a heap onto itself (close pairs across layers), with a picker closing on it."""
    rest = physics.mesh.rest_positions
    fold = np.where(rest[:, 0] > 0, 1.0, 0.0)[:, None]  # the right half laid back over the left, 1.2 cm up
    x = rest.copy()
    x[:, 0] = np.where(fold[:, 0] > 0, -rest[:, 0], rest[:, 0])
    x[:, 2] = 0.008 + 0.012 * fold[:, 0]
    x = jnp.asarray(x) + 0.002 * jax.random.normal(key, x.shape)
    state = physics.state_from_positions(x)
    return state.replace(velocities=0.05 * jax.random.normal(jax.random.fold_in(key, 1), x.shape),
                         picker_positions=jnp.tile(x[physics.mesh.index(3, 6)] + jnp.array([0, 0, 0.005]),
                                                   (physics.num_pickers, 1)))


@functools.cache
def _solvers(pickers):
    """MESH's jax.numpy and fused solvers with ``pickers`` pickers, 4 substeps: ``(xla, fused, params, xla step,
    fused step)``, the steps jitted once for the module. Interpreted on the CPU, each fused step program takes
    ~16 s to compile whatever the cloth's size (its run takes milliseconds), so the tests share them."""
    xla = ClothPhysics(MESH, num_pickers=pickers, solver="xla", substeps=4)
    kernel = dataclasses.replace(xla, solver="fused")
    return xla, kernel, xla.default_params(), jax.jit(xla.step), jax.jit(kernel.step)


@pytest.mark.parametrize("pickers", [1, 2])
def test_the_fused_kernel_matches_the_jax_numpy_solver(pickers):
    xla, kernel, params, xla_step, kernel_step = _solvers(pickers)
    state = _crumpled(xla, jax.random.key(pickers))
    grasp = jnp.tile(jnp.array([[0.0, 0.0, 0.0, 1.0]]), (pickers, 1))
    lift = jnp.tile(jnp.array([[0.01, -0.005, 0.02, 1.0]]), (pickers, 1))
    a, b = state, state
    for control in (grasp, lift, lift):
        a, b = xla_step(a, control, params), kernel_step(b, control, params)
        assert bool(a.grasped.any())
        np.testing.assert_allclose(np.asarray(b.positions), np.asarray(a.positions), atol=2e-6)
        np.testing.assert_allclose(np.asarray(b.velocities), np.asarray(a.velocities), atol=2e-3)
    assert float(jnp.abs(a.positions - state.positions).max()) > 0.01  # it moved: the comparison means something


def test_the_fused_kernel_runs_batched_and_every_cloth_alone_gives_the_same():
    # the one-picker cloth of the test above (4 substeps): its single-cloth step is compiled once for both
    _, physics, params, _, step = _solvers(1)
    states = jax.vmap(lambda k: _crumpled(physics, k))(jax.random.split(jax.random.key(0), 3))
    control = jnp.array([[0.0, 0.0, 0.01, 1.0]])
    many = jax.jit(jax.vmap(physics.step, in_axes=(0, None, None)))(states, control, params)
    for i in range(3):
        one = step(jax.tree_util.tree_map(lambda x: x[i], states), control, params)
        # (interpreted on the CPU, XLA may round the last bit differently for another batch size; on a GPU each
        # cloth is one program of the same code, whatever the batch)
        np.testing.assert_allclose(np.asarray(many.positions[i]), np.asarray(one.positions), atol=1e-6)


def test_a_cloth_solver_must_be_known():
    with pytest.raises(ValueError, match="unknown cloth solver 'cuda'; valid: auto, xla, fused"):
        ClothPhysics(MESH, solver="cuda")


def test_each_colour_role_names_the_pairs_the_jax_numpy_solver_solves_in_that_colour():
    n, n_pad = MESH.num_particles, fused.padded_size(MESH.num_particles)
    roles = fused.colour_roles(MESH).reshape(len(fused.COLOURS), n_pad)
    for role, pairs in zip(roles, _constraint_pairs(MESH.rows, MESH.cols), strict=True):
        i, j = np.nonzero(pairs.mask)
        j = j + (1 if pairs.dj < 0 else 0)
        expected = {(int(a), int(a + pairs.di * MESH.cols + pairs.dj)) for a in i * MESH.cols + j}
        first, second, partner = (role & 1) != 0, (role & 2) != 0, role >> 2
        assert {(int(a), int(partner[a])) for a in np.nonzero(first)[0]} == expected
        assert {(int(partner[b]), int(b)) for b in np.nonzero(second)[0]} == expected
        assert not (first & second).any() and not (first | second)[n:].any()  # padding pairs with none
        alone = np.nonzero(~first[:n] & ~second[:n])[0]
        assert (partner[alone] == alone).all()  # a particle without a pair is its own partner


def test_kernel_programs_have_power_of_two_sizes():
    assert [fused.padded_size(n) for n in (63, 64, 65, 1600, 4096)] == [64, 64, 128, 2048, 4096]


def test_kernel_programs_run_two_particles_per_thread_in_4_to_32_warps():
    assert [fused.default_warps(n) for n in (16, 256, 1024, 2048, 4096, 16384)] == [4, 4, 16, 32, 32, 32]


LIST_MESH = ClothMesh(rows=10, cols=12, spacing=0.01)
RADIUS = jnp.float32(0.016)


@functools.cache
def _kernel_list(slots):
    """The kernel's list of LIST_MESH's pairs within RADIUS, keeping ``slots`` candidates: one jitted program per
    ``slots`` for the module (interpreted, each takes ~10 s to compile)."""
    return jax.jit(lambda x: fused.neighbour_list(LIST_MESH, x, RADIUS, slots=slots))


_xla_list = jax.jit(lambda x: neighbours_xla(LIST_MESH, x, RADIUS))  # one program, not hundreds of eager ops


# a loose heap, one piled past the list's slots (overflow), and one with more candidates than the kernel keeps
@pytest.mark.parametrize("size, kept", [(0.05, 64), (0.02, 64), (0.02, 4)])
def test_the_kernel_lists_the_pairs_the_jax_numpy_list_does(size, kept):
    x = jnp.asarray(np.random.default_rng(0).uniform(0, size, (LIST_MESH.num_particles, 3)).astype(np.float32))
    expect, _ = _xla_list(x)
    found, overflow = _kernel_list(kept)(x)
    np.testing.assert_array_equal(np.asarray(found), np.asarray(expect))  # the same pairs, in the same order
    listed = {(i, int(q)) for i, row in enumerate(np.asarray(found)) for q in row if q >= 0}
    assert listed and all((q, i) in listed for i, q in listed)  # every pair listed by both its particles
    d = np.linalg.norm(np.asarray(x)[:, None] - np.asarray(x)[None], axis=-1)
    assert all(d[i, q] < 0.016 for i, q in listed)
    assert (int(overflow) > 0) == (size < 0.03)


def test_which_walk_program_a_particle_is_dealt_to_changes_nothing_in_the_list(monkeypatch):
    # the walk's programs are dealt particles busiest first; dealt quietest first, in programs of 32, the list is
    # the same (each particle's candidates are walked in the same order whichever program walks them). A loose
    # heap: no particle has more candidates within the radius than the walk keeps, so the listing reads those
    x = jnp.asarray(np.random.default_rng(2).uniform(0, 0.05, (LIST_MESH.num_particles, 3)).astype(np.float32))

    @jax.jit
    def candidates(x):
        cell, _, _, count = collision.sorted_cells(x, RADIUS)
        return fused.candidate_counts(cell, x, RADIUS, count)

    busy = candidates(x)
    assert int(busy.max()) > 2 * int(busy.min())  # a deal that matters: the particles' walks differ in length
    monkeypatch.setattr(fused, "LIST_BLOCK", 32)
    monkeypatch.setattr(fused, "candidate_counts", lambda *args: -busy)
    fused._list_calls.cache_clear()
    try:  # traced afresh (not _kernel_list's program): the walk is built with the patched deal
        found, _ = jax.jit(lambda x: fused.neighbour_list(LIST_MESH, x, RADIUS))(x)
    finally:
        fused._list_calls.cache_clear()
    np.testing.assert_array_equal(np.asarray(found), np.asarray(_xla_list(x)[0]))


def test_the_kernel_lists_pairs_just_within_the_radius_across_a_cell_corner():
    # the list skips neighbour cells beyond the radius: a pair that straddles a corner of the cells, just within
    # the radius, must still be listed (each pair far from the others, particles k and k + 60 five rows apart)
    radius = 0.016
    rng = np.random.default_rng(1)
    x = np.stack([np.arange(120) * 10.0, np.full(120, 40.0), np.full(120, 20.0)], -1) * radius
    for k in range(20):
        corner = np.array([10.0 * k + 3, 7.0, 3.0]) * radius  # a corner shared by 8 cells
        u = rng.uniform(0.2, 1.0, 3)
        u /= np.linalg.norm(u)
        distance = rng.uniform(0.95, 0.999) * radius
        before = rng.uniform(0.05, 0.95) * distance
        x[k], x[k + 60] = corner - before * u, corner + (distance - before) * u
    x = jnp.asarray(x.astype(np.float32))
    found = np.asarray(_kernel_list(64)(x)[0])
    assert all(found[k, 0] == k + 60 and found[k + 60, 0] == k for k in range(20))
    np.testing.assert_array_equal(found, np.asarray(_xla_list(x)[0]))


def test_the_arena_string_names_the_valid_solvers():
    import jarena
    from jarena.building import ArenaStringError

    with pytest.raises(ArenaStringError, match="unknown cloth solver 'cuda'; valid choices: auto, xla, fused"):
        jarena.build_arena("cloth|solver:cuda")
    assert jarena.build_arena("cloth|solver:xla").dynamics.step.__self__.resolve_solver() == "xla"
