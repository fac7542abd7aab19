"""The PushT task: cover the goal T with the block (``pusht_env``'s reward, success and Diffusion Policy's score)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from jarena.arenas.pusht import geometry
from jarena.arenas.pusht.overlap import coverage
from jarena.arenas.pusht.physics import block_pose
from jarena.core.task import Task

_coverage = jax.jit(coverage)  # one program where a step runs eagerly (inlined under the caller's jit)


@struct.dataclass
class PushTaskParams:
    """``goal``: float32 (3,), the goal pose ``(x, y, angle)``; ``success_coverage``: the coverage beyond which
    the episode succeeds and ends (``pusht_env``'s 0.95), which also scales the reward."""

    goal: jax.Array = struct.field(default_factory=lambda: jnp.asarray(geometry.GOAL_POSE, jnp.float32))
    success_coverage: jax.Array = 0.95


def push_t() -> Task:
    """Push the T onto the goal.

    - ``coverage``: ``area(T ∩ goal) / area(goal)`` after each step (:func:`.overlap.coverage`, exact).
    - reward: ``clip(coverage / success_coverage, 0, 1)``; success and termination: ``coverage >
      success_coverage``, as ``pusht_env``.
    - ``max_coverage`` and ``max_reward``: the largest coverage and reward over the steps taken so far (0 at
      reset). Diffusion Policy scores an episode by its largest reward (``max_reward`` at its last step, averaged
      over episodes: "target area coverage"); the fraction of episodes that succeed is the stricter figure.
    - ``info.goal``: the goal pose (3,).
    """

    def measure(physics, params):
        covered = _coverage(block_pose(physics), params.goal)
        reward = jnp.clip(covered / params.success_coverage, 0.0, 1.0)
        return covered, reward, covered > params.success_coverage

    def reset(key, physics, outcome, params):
        covered = _coverage(block_pose(physics), params.goal)
        zero = jnp.zeros((), jnp.float32)
        metrics = dict(outcome.metrics, coverage=covered, max_coverage=zero, max_reward=zero)
        return outcome.replace(success=covered > params.success_coverage, goal=params.goal, metrics=metrics), \
            (zero, zero)

    def update(state, outcome, transition, params):
        best_coverage, best_reward = state
        covered, reward, success = measure(transition.physics, params)
        best_coverage, best_reward = jnp.maximum(best_coverage, covered), jnp.maximum(best_reward, reward)
        metrics = dict(outcome.metrics, coverage=covered, max_coverage=best_coverage, max_reward=best_reward)
        return outcome.replace(reward=outcome.reward + reward, success=success, terminated=outcome.terminated | success,
                               goal=params.goal, metrics=metrics), (best_coverage, best_reward)

    return Task(update=update, reset=reset, name="push_t", has_success=True,
                default_params=lambda: jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float32),
                                                              PushTaskParams()))
