"""Cloth folding tasks: the folded goals, their distances, info.goal and the horizons."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.arenas.cloth import coverage, tasks
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import ClothState
from jarena.core.types import Outcome, Transition

FOLDS = ["side_fold", "diagonal_fold", "one_corner_inward"]


def _arena(kind: str, initial: str = "flat", extra: str = "") -> jarena.Arena:
    return jarena.build_arena(f"cloth|task:{kind},initial:{initial},particles:12,resolution:32{extra}")


def _pose(mesh: ClothMesh, angle: float, mirror: bool, shift) -> np.ndarray:
    rest = mesh.rest_positions.astype(np.float64)
    xy = rest[:, :2] * (np.array([1.0, -1.0]) if mirror else 1.0)
    c, s = np.cos(angle), np.sin(angle)
    xy = xy @ np.array([[c, s], [-s, c]]) + np.asarray(shift)
    return np.concatenate([xy, np.full((len(xy), 1), 0.4 * mesh.spacing)], -1).astype(np.float32)


@pytest.mark.parametrize("kind", FOLDS)
@pytest.mark.parametrize("mirror", [False, True])
def test_goals_are_the_flat_cloth_folded_in_its_own_pose(kind, mirror):
    mesh = ClothMesh.of_size(0.5, 0.3, cols=11)
    flat = _pose(mesh, 0.7, mirror, (0.05, -0.08))
    goals = np.asarray(tasks.folded_goals(mesh, kind, jnp.asarray(flat)))
    assert goals.shape == (4, mesh.num_particles, 3)
    material = mesh.rest_positions[:, :2]
    for fold, goal in zip(tasks.FOLDS[kind](mesh), goals, strict=True):
        moving = fold.moving(material)
        assert 0 < moving.sum() < mesh.num_particles
        # the staying side keeps its place, the folded side lies one layer gap above
        np.testing.assert_allclose(goal[~moving], flat[~moving], atol=1e-5)
        np.testing.assert_allclose(goal[moving, 2], 1.2 * mesh.spacing, atol=1e-6)
        # the folded side is reflected: distances within it, seen from above, are kept
        pairs = np.random.default_rng(0).choice(np.flatnonzero(moving), (200, 2))
        before = np.linalg.norm(flat[pairs[:, 0], :2] - flat[pairs[:, 1], :2], axis=-1)
        after = np.linalg.norm(goal[pairs[:, 0], :2] - goal[pairs[:, 1], :2], axis=-1)
        np.testing.assert_allclose(after, before, atol=1e-5)


def test_each_fold_moves_what_its_name_says():
    mesh = ClothMesh.of_size(0.4, 0.4, cols=21)
    flat = jnp.asarray(mesh.rest_positions)
    side, diagonal, corner = (np.asarray(tasks.folded_goals(mesh, k, flat))[0] for k in FOLDS)
    c = mesh.corners
    area = jax.jit(lambda x: coverage.coverage(x, mesh))  # one compiled call for the three, not op by op
    # a side fold halves the cloth's footprint; a diagonal fold brings a corner onto the opposite one
    assert float(area(jnp.asarray(side))) == pytest.approx(mesh.area / 2, rel=0.03)
    assert float(area(jnp.asarray(diagonal))) == pytest.approx(mesh.area / 2, rel=0.08)
    np.testing.assert_allclose(diagonal[c[2], :2], mesh.rest_positions[c[0], :2], atol=1e-6)
    # one corner inward: the corner lands on the centre, an eighth of the cloth is folded
    np.testing.assert_allclose(corner[c[2], :2], [0.0, 0.0], atol=1e-6)
    assert float(area(jnp.asarray(corner))) == pytest.approx(mesh.area * 7 / 8, rel=0.03)


def _measure(kind: str, start: np.ndarray, now: np.ndarray, mesh: ClothMesh):
    """The folding task's outcome for a cloth that started at ``start`` and is at ``now``."""
    task = tasks.folding(mesh, kind)
    params = task.default_params()
    physics = lambda x: ClothState(positions=jnp.asarray(x), velocities=jnp.zeros_like(jnp.asarray(x)),  # noqa: E731
                                   picker_positions=jnp.zeros((1, 3)), picker_closed=jnp.zeros((1,), bool),
                                   held=-jnp.ones((1, 4), jnp.int32), held_offsets=jnp.zeros((1, 4, 3)), mesh=mesh)
    first, state = task.reset(jax.random.key(0), physics(start), Outcome.empty(), params)
    outcome, _ = task.update(state, Outcome.empty(), Transition(physics(start), None, physics(now)), params)
    return first, outcome


@pytest.mark.parametrize("kind", FOLDS)
def test_the_distance_is_one_unfolded_and_zero_at_any_variant_of_the_goal(kind):
    mesh = ClothMesh.of_size(0.4, 0.4, cols=12)
    flat = _pose(mesh, -0.4, True, (0.02, 0.03))
    goals = np.asarray(tasks.folded_goals(mesh, kind, jnp.asarray(flat)))
    first, outcome = _measure(kind, flat, flat, mesh)
    assert first.goal.shape == (mesh.num_particles * 3,)
    np.testing.assert_allclose(np.asarray(first.goal), goals[0].reshape(-1), atol=1e-6)
    assert float(outcome.metrics["normalised_fold_distance"]) == pytest.approx(1.0, abs=1e-3)
    assert not bool(outcome.success)
    for goal in goals:  # a uniform cloth has no marked side: every variant counts
        _, outcome = _measure(kind, flat, goal, mesh)
        assert float(outcome.metrics["fold_distance"]) < 1e-5
        assert bool(outcome.success)
        assert float(outcome.metrics["fold_improvement"]) == pytest.approx(1.0, abs=1e-4)
    # halfway there: the normalised distance is about a half, and the reward is minus it
    _, outcome = _measure(kind, flat, (flat + goals[0]) / 2, mesh)
    assert 0.3 < float(outcome.metrics["normalised_fold_distance"]) <= 0.5 + 1e-4
    assert float(outcome.reward) == pytest.approx(-float(outcome.metrics["normalised_fold_distance"]))


def test_the_arena_puts_the_goal_in_info():
    arena = _arena("side_fold")

    @jax.jit  # one compiled call: run op by op, the reset and the step dispatch thousands of small programs
    def reset_and_step():
        state, info = arena.reset(episode=0)
        goals = tasks.folded_goals(state.physics.mesh, "side_fold", state.physics.positions)
        return state, info, goals, arena.step(state, -jnp.ones(arena.action_spec.shape))[1]

    state, info, goals, stepped = reset_and_step()
    n = state.physics.positions.shape[0]
    assert arena.goal_dim == n * 3
    np.testing.assert_allclose(np.asarray(info.goal), np.asarray(goals[0]).reshape(-1), atol=1e-6)
    assert float(info.metrics["normalised_fold_distance"]) == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(np.asarray(stepped.goal), np.asarray(goals[0]).reshape(-1), atol=1e-6)


def test_crumpled_folds_aim_at_the_canonical_pose_and_get_time_to_flatten():
    flat, crumpled = _arena("diagonal_fold"), _arena("diagonal_fold", initial="crumpled")
    assert flat.max_episode_steps == 15 and crumpled.max_episode_steps == 45
    assert _arena("side_fold", extra=",horizon:3").max_episode_steps == 3

    @jax.jit  # one compiled call: run op by op, the crumpling reset dispatches thousands of small programs
    def goal_and_canonical():
        state, info = crumpled.reset(episode=0)
        return info.goal, tasks.folded_goals(state.physics.mesh, "diagonal_fold",
                                             jnp.asarray(state.physics.mesh.rest_positions))[0]

    goal, canonical = (np.asarray(x) for x in goal_and_canonical())
    np.testing.assert_allclose(goal.reshape(-1, 3), canonical, atol=1e-6)


def test_goal_image_shows_the_folded_cloth():
    arena = _arena("side_fold")
    state, info = jax.jit(arena.reset)(jax.random.key(0))
    mesh = state.physics.mesh
    image = jax.jit(lambda goal: tasks.goal_image(goal, mesh, 64))(info.goal)  # one compiled call, not op by op
    start = np.asarray(info.observation["mask"]).mean()
    # (observation at 32 px, goal image at 64 px: compare the fractions of the view the cloth fills)
    assert np.asarray(image["mask"]).mean() == pytest.approx(start / 2, rel=0.15)
    assert image["rgb"].shape == (64, 64, 3)
