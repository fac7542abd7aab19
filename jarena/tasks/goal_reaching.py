"""``goal_reaching``: reach a goal position sampled per episode."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.task import Task

REWARDS = ("dense", "sparse")


@struct.dataclass
class GoalReachingParams:
    """low, high: float32 (goal_dim,) box the goal is drawn from; threshold: success radius."""

    low: jax.Array
    high: jax.Array
    threshold: jax.Array


def goal_reaching(position: Callable[[Any], jax.Array], low, high, threshold: float = 0.05,
                  reward: str = "dense", terminate_on_success: bool = False) -> Task:
    """Samples a goal uniformly in ``[low, high]`` per episode and rewards getting ``position`` to it.

    Works on any dynamics given ``position(physics) -> (goal_dim,) float32``. The goal is exposed in
    ``info.goal``; metric ``distance`` is the Euclidean distance to it.

    Args:
      position: maps the physics state to the controlled point, shape (goal_dim,).
      low: lower corner of the goal box, shape (goal_dim,).
      high: upper corner of the goal box, shape (goal_dim,).
      threshold: success when ``distance < threshold``.
      reward: ``dense`` (minus the distance, per step) or ``sparse`` (1 on success steps).
      terminate_on_success: end the episode on success.
    """
    if reward not in REWARDS:
        raise ValueError(f"goal_reaching reward must be one of {list(REWARDS)}, got {reward!r}")
    low = jnp.asarray(low, jnp.float32).reshape(-1)
    high = jnp.asarray(high, jnp.float32).reshape(-1)
    if low.shape != high.shape:
        raise ValueError(f"goal_reaching low and high differ in shape: {low.shape} vs {high.shape}")

    def distance(goal, physics):
        return jnp.linalg.norm(jnp.asarray(position(physics), jnp.float32) - goal)

    def reset(key, physics, outcome, params):
        goal = jax.random.uniform(key, params.low.shape, jnp.float32, params.low, params.high)
        d = distance(goal, physics)
        terms = dict(outcome.reward_terms, goal_reaching=jnp.zeros((), jnp.float32))
        return outcome.replace(goal=goal, success=d < params.threshold, reward_terms=terms,
                               metrics=dict(outcome.metrics, distance=d)), goal

    def update(goal, outcome, transition, params):
        d = distance(goal, transition.physics)
        success = d < params.threshold
        r = -d if reward == "dense" else success.astype(jnp.float32)
        terminated = outcome.terminated | success if terminate_on_success else outcome.terminated
        return outcome.replace(reward=outcome.reward + r, goal=goal, success=success, terminated=terminated,
                               reward_terms=dict(outcome.reward_terms, goal_reaching=r),
                               metrics=dict(outcome.metrics, distance=d)), goal

    return Task(update=update, reset=reset,
                default_params=lambda: GoalReachingParams(low, high, jnp.asarray(threshold, jnp.float32)),
                name="goal_reaching", has_success=True)
