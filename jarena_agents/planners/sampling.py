"""What the sampling planners share: action bounds, sampling plans around a mean, scoring rollouts, warm start.

Shapes for one arena (planners vmap over arenas): a plan is ``(H, *action_shape)`` float32 (H = horizon,
in agent steps); N sampled plans are ``(N, H, *action_shape)``; scores are ``(N,)`` float32.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena_agents.planners.model import Model

PyTree = Any

WARM_STARTS = ("last", "no_op")


def action_bounds(model: Model) -> tuple[jax.Array, jax.Array]:
    """``(low, high)`` float32 arrays of the action shape."""
    spec = model.action_spec
    return jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)


def half_range(model: Model) -> jax.Array:
    """Half the width of the action bounds, ``(high - low) / 2`` (the unit of the planners' noise)."""
    low, high = action_bounds(model)
    return (high - low) / 2.0


def initial_plan(model: Model, horizon: int) -> jax.Array:
    """The plan of a new episode: the no-op action at every step, ``(H, *action_shape)``."""
    no_op = jnp.asarray(np.broadcast_to(model.no_op, model.action_spec.shape), jnp.float32)
    return jnp.broadcast_to(no_op, (horizon,) + no_op.shape)


def sample_plans(key: jax.Array, mean: jax.Array, std: jax.Array | float, num: int, low: jax.Array,
                 high: jax.Array) -> jax.Array:
    """``num`` plans ``clip(mean + std * normal, low, high)``, the first of them the (clipped) mean itself.

    Args:
      key: PRNG key.
      mean: ``(H, *action_shape)`` plan to sample around.
      std: noise standard deviation, broadcastable to ``mean`` (action units).
      num: N, number of plans (N >= 1; with N = 1 only the mean).
      low: lower action bounds, broadcastable to ``mean``.
      high: upper action bounds, broadcastable to ``mean``.

    Returns:
      ``(N, H, *action_shape)`` float32.
    """
    noise = jax.random.normal(key, (num,) + mean.shape, jnp.float32) * std
    noise = noise.at[0].set(0.0)
    return jnp.clip(mean[None] + noise, low, high)


def rollout_returns(model: Model, state: PyTree, plans: jax.Array) -> jax.Array:
    """Scores of ``plans`` ``(N, H, *action_shape)`` from ``state``: the sum of the model's rewards over the
    horizon, counting the step that ends the episode and nothing after it. ``lax.scan`` over the horizon,
    ``vmap`` over the plans; returns ``(N,)`` float32."""

    def score(plan):
        def body(carry, action):
            state, alive, total = carry
            state, reward, done = model.step(state, action)
            total = total + jnp.where(alive, reward, 0.0)
            return (state, alive & ~done, total), None

        carry = (state, jnp.ones((), bool), jnp.zeros((), jnp.float32))
        (_, _, total), _ = jax.lax.scan(body, carry, plan)
        return total

    return jax.vmap(score)(plans)


def shift_plan(plan: jax.Array, fill: jax.Array) -> jax.Array:
    """The plan for the next step: drop the action just taken and append ``fill`` at the end.

    Args:
      plan: ``(H, *action_shape)``.
      fill: the action to append, ``action_shape``.
    """
    return jnp.concatenate([plan[1:], jnp.broadcast_to(fill, plan.shape[1:])[None]], axis=0)


def warm_start_fill(plan: jax.Array, model: Model, warm_start: str) -> jax.Array:
    """The action :func:`shift_plan` appends: the plan's last action (``last``) or the no-op (``no_op``)."""
    if warm_start == "last":
        return plan[-1]
    if warm_start == "no_op":
        return jnp.broadcast_to(jnp.asarray(model.no_op, plan.dtype), plan.shape[1:])
    raise ValueError(f"warm_start must be one of {list(WARM_STARTS)}, got {warm_start!r}")
