"""Cloth tasks: flattening (SoftGym's coverage metrics) and folding (particle distance to a folded goal).

Tasks run after every physics step; inside a pick-and-place only the last step's outcome is used, and
XLA removes the earlier steps' metric computations (dead code).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from jarena.arenas.cloth import coverage as coverage_lib
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.task import Task
from jarena.core.tree import as_float32


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
        metrics = {"coverage": cov, "normalised_coverage": normalised, "normalised_improvement": improvement}
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
