"""Cloth tasks: flattening (SoftGym's coverage metrics) and folding (particle distance to a folded goal).

Tasks run after every physics step; inside a pick-and-place only the last step's outcome is used, and
XLA removes the earlier steps' metric computations (dead code).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.cloth import camera as camera_lib
from jarena.arenas.cloth import coverage as coverage_lib
from jarena.arenas.cloth.collision import dot, fixed_matmul, fixed_sum
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.task import Task
from jarena.core.tree import as_float32


def physics_metrics(physics) -> dict[str, jax.Array]:
    """Metrics every cloth task reports about its simulation: ``collision_overflow``, the particles the
    self-collision search could not read in the last physics step (0 unless piled deeper than it reads;
    see :class:`.physics.ClothState`)."""
    return {"collision_overflow": jnp.asarray(physics.collision_overflow, jnp.float32)}


@struct.dataclass
class FlatteningParams:
    """``success_coverage``: normalised coverage at which flattening succeeds (Agent-Arena's 0.99)."""

    success_coverage: jax.Array = 0.99


def flattening(mesh: ClothMesh) -> Task:
    """Flatten the cloth: maximise the area of its top-down projection.

    - ``coverage``: that area, m^2 (:mod:`.coverage`, from the particles, independent of the camera).
    - ``normalised_coverage``: coverage / the flat cloth's area, clipped to [0, 1] (SoftGym's).
    - ``normalised_improvement``: (coverage - initial) / (flat - initial), SoftGym's performance measure
      (1 where the episode started flat).
    - reward: the normalised coverage after each action; success: normalised coverage >=
      ``success_coverage``. Agent-Arena also asks that all four corners be visible; a cloth at 0.99 coverage
      has its corners out, so the coverage alone is used here.
    """
    area = float(mesh.area)

    def measure(physics, initial, params):
        cov = coverage_lib.coverage(physics.positions, mesh)
        normalised = jnp.clip(cov / area, 0.0, 1.0)
        improvement = jnp.where(area - initial > 1e-9, (cov - initial) / jnp.maximum(area - initial, 1e-9), 1.0)
        metrics = {"coverage": cov, "normalised_coverage": normalised, "normalised_improvement": improvement,
                   **physics_metrics(physics)}
        return normalised, normalised >= params.success_coverage, metrics

    def reset(key, physics, outcome, params):
        initial = coverage_lib.coverage(physics.positions, mesh)
        _, success, metrics = measure(physics, initial, params)
        return outcome.replace(success=success, metrics=dict(outcome.metrics, **metrics),
                               reward_terms=dict(outcome.reward_terms, normalised_coverage=jnp.zeros((), jnp.float32))
                               ), initial

    def update(initial, outcome, transition, params):
        normalised, success, metrics = measure(transition.physics, initial, params)
        return outcome.replace(reward=outcome.reward + normalised, success=success,
                               reward_terms=dict(outcome.reward_terms, normalised_coverage=normalised),
                               metrics=dict(outcome.metrics, **metrics)), initial

    return Task(update=update, reset=reset, default_params=lambda: as_float32(FlatteningParams()),
                name="flattening", has_success=True)


# ---------------------------------------------------------------------------------------------- folding
@dataclasses.dataclass(frozen=True)
class Fold:
    """A fold line on the flat cloth, in its material coordinates (the rest grid's x-y, centred, metres):
    particles ``m`` with ``normal . m > offset`` fold over the line onto the others (reflected across it)."""

    normal: tuple[float, float]
    offset: float

    def moving(self, material: np.ndarray) -> np.ndarray:
        """bool (N,): the particles on the folding side (a particle on the line stays)."""
        return material @ np.asarray(self.normal) > self.offset + 1e-6

    def reflect(self, material: np.ndarray) -> np.ndarray:
        """float (N, 2): where each particle lies after the fold (the moving side reflected, the rest kept)."""
        n = np.asarray(self.normal)
        side = material @ n - self.offset
        return np.where(self.moving(material)[:, None], material - 2.0 * side[:, None] * n, material)


def _unit(x: float, y: float) -> tuple[float, float]:
    norm = float(np.hypot(x, y))
    return (x / norm, y / norm)


def _side_folds(mesh: ClothMesh) -> list[Fold]:
    """Fold in half along either centre line, either half on top (4 variants)."""
    return [Fold((1.0, 0.0), 0.0), Fold((-1.0, 0.0), 0.0), Fold((0.0, 1.0), 0.0), Fold((0.0, -1.0), 0.0)]


def _diagonal_folds(mesh: ClothMesh) -> list[Fold]:
    """Bring a corner onto the opposite corner (the fold line bisects the diagonal between them; on a square
    it is the other diagonal): 4 variants."""
    a, b = mesh.width / 2, mesh.height / 2
    return [Fold(_unit(sx * a, sy * b), 0.0) for sx, sy in [(1, 1), (-1, -1), (1, -1), (-1, 1)]]


def _corner_inward_folds(mesh: ClothMesh) -> list[Fold]:
    """Bring one corner onto the cloth's centre (the fold line bisects the segment between them): 4 variants."""
    a, b = mesh.width / 2, mesh.height / 2
    half = float(np.hypot(a, b)) / 2
    return [Fold(_unit(sx * a, sy * b), half) for sx, sy in [(1, 1), (-1, 1), (-1, -1), (1, -1)]]


FOLDS = {"side_fold": _side_folds, "diagonal_fold": _diagonal_folds, "one_corner_inward": _corner_inward_folds}
"""Folding task -> ``(mesh) -> [Fold, ...]``, its symmetric variants (the first is the one in ``info.goal``)."""


@struct.dataclass
class FoldingParams:
    """``success_distance``: the normalised fold distance at or under which folding succeeds."""

    success_distance: jax.Array = 0.1


def folded_goals(mesh: ClothMesh, kind: str, flat: jax.Array) -> jax.Array:
    """float32 (V, N, 3): the goal configurations of folding task ``kind``, one per symmetric variant.

    ``flat`` (N, 3) is the flat cloth the fold starts from (any rigid pose in the plane, face up or down): the
    goals are the folds of ``FOLDS[kind]`` mapped into that pose (the least-squares affine map from the rest
    grid to ``flat``'s x-y, exact for a flat cloth), the folded layer one layer gap (0.8 x spacing, the
    collision distance) above the floor layer, which rests at the particle radius (0.4 x spacing).
    """
    material = np.asarray(mesh.rest_positions[:, :2], np.float64)
    gram_inverse = np.linalg.inv(material.T @ material).astype(np.float32)
    centre = fixed_sum(flat[:, :2], axis=0) / flat.shape[0]
    cross = fixed_sum((flat[:, :2] - centre)[:, :, None] * jnp.asarray(material, jnp.float32)[:, None, :], axis=0)
    linear = fixed_matmul(cross, gram_inverse)  # (2, 2): world x-y = linear @ material + centre
    goals = []
    for fold in FOLDS[kind](mesh):
        folded = fixed_matmul(jnp.asarray(fold.reflect(material), jnp.float32), linear.T) + centre
        z = np.where(fold.moving(material), 1.2, 0.4) * mesh.spacing
        goals.append(jnp.concatenate([folded, jnp.asarray(z, jnp.float32)[:, None]], axis=-1))
    return jnp.stack(goals)


def unfolded_distances(mesh: ClothMesh, kind: str) -> np.ndarray:
    """float32 (V,): mean particle distance between the flat cloth and each variant's goal, metres (any pose)."""
    material = np.asarray(mesh.rest_positions[:, :2], np.float64)
    out = []
    for fold in FOLDS[kind](mesh):
        lift = np.where(fold.moving(material), 0.8 * mesh.spacing, 0.0)
        shift = fold.reflect(material) - material
        out.append(np.mean(np.sqrt(np.sum(shift * shift, axis=-1) + lift * lift)))
    return np.asarray(out, np.float32)


def _mean_distance(positions: jax.Array, goal: jax.Array) -> jax.Array:
    d = positions - goal
    return fixed_sum(jnp.sqrt(dot(d, d)), axis=0) / goal.shape[0]


def folding(mesh: ClothMesh, kind: str, canonical: bool = False) -> Task:
    """Fold the cloth: ``kind`` in :data:`FOLDS` (``side_fold``, ``diagonal_fold``, ``one_corner_inward``).

    The goal is set at reset from the initial cloth: its folded configurations (:func:`folded_goals`) in the
    initial pose, or, when ``canonical`` (a crumpled start, which has no flat pose), in the canonical pose
    (centred, axis-aligned, face up). ``info.goal`` holds the first variant's particle positions, float32
    (N x 3,) flattened, metres; :func:`goal_image` renders it with the top-down camera.

    - ``fold_distance``: mean particle distance to the goal, metres, for the variant where it is smallest
      relative to the unfolded cloth's (a fold of either half or any corner counts: a uniform cloth has no
      marked side).
    - ``normalised_fold_distance``: that distance over the flat, unfolded cloth's distance to the same goal
      (:func:`unfolded_distances`): 1 for the unfolded cloth, 0 for the goal.
    - ``fold_improvement``: 1 - fold_distance / its value at the start.
    - reward: ``-normalised_fold_distance`` after each action; success: ``normalised_fold_distance <=
      success_distance`` (default 0.1).
    """
    if kind not in FOLDS:
        raise ValueError(f"unknown fold {kind!r}; choose from {sorted(FOLDS)}")
    rest = jnp.asarray(mesh.rest_positions)
    unfolded = jnp.asarray(unfolded_distances(mesh, kind))

    def distances(positions, goals):
        """(fold_distance, normalised) of the variant nearest relative to its unfolded distance."""
        raw = jnp.stack([_mean_distance(positions, g) for g in goals])
        best = jnp.argmin(raw / unfolded)
        return raw[best], raw[best] / unfolded[best]

    def measure(physics, goals, initial, params):
        distance, normalised = distances(physics.positions, goals)
        improvement = 1.0 - distance / jnp.maximum(initial, 1e-9)
        metrics = {"fold_distance": distance, "normalised_fold_distance": normalised,
                   "fold_improvement": improvement, **physics_metrics(physics)}
        return normalised, normalised <= params.success_distance, metrics

    def reset(key, physics, outcome, params):
        goals = folded_goals(mesh, kind, rest if canonical else physics.positions)
        initial, _ = distances(physics.positions, goals)
        _, success, metrics = measure(physics, goals, initial, params)
        terms = dict(outcome.reward_terms, normalised_fold_distance=jnp.zeros((), jnp.float32))
        return outcome.replace(goal=goals[0].reshape(-1), success=success, metrics=dict(outcome.metrics, **metrics),
                               reward_terms=terms), (goals, initial)

    def update(state, outcome, transition, params):
        goals, initial = state
        normalised, success, metrics = measure(transition.physics, goals, initial, params)
        return outcome.replace(reward=outcome.reward - normalised, success=success, goal=goals[0].reshape(-1),
                               reward_terms=dict(outcome.reward_terms, normalised_fold_distance=-normalised),
                               metrics=dict(outcome.metrics, **metrics)), state

    return Task(update=update, reset=reset, default_params=lambda: as_float32(FoldingParams()), name=kind,
                has_success=True)


def goal_image(goal: jax.Array, mesh: ClothMesh, resolution: int = 128,
               camera: camera_lib.CameraParams | None = None) -> dict[str, jax.Array]:
    """The top-down camera's view of a folding goal (``info.goal``, (N x 3,)): ``rgb``, ``depth``, ``mask``."""
    camera = camera_lib.CameraParams() if camera is None else camera
    return camera_lib.render(goal.reshape(-1, 3), mesh, camera, int(resolution))
