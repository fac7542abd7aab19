"""``noise``: perturb actions (Gaussian for Box actions, epsilon-random for Discrete)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.core.spec import Box, Discrete
from jarena.core.tool import ActionTool


def noise(scale: float = 0.1) -> ActionTool:
    """Adds action noise; the spec is unchanged.

    Box: adds ``scale * N(0, 1)`` per dimension (in action units) and clips to the bounds if bounded.
    Discrete: replaces the action by a uniformly random one with probability ``scale``.
    State: a PRNG key (from the episode key). Params: float32 ``scale`` (vmappable).
    """
    if scale < 0:
        raise ValueError(f"noise needs scale >= 0, got {scale}")

    def reset(key, params, inner):
        if not isinstance(inner, Box | Discrete):
            raise TypeError(f"noise applies to Box or Discrete actions, got {inner!r}")
        return key

    def step(key, action, carry, inner_step, params, inner):
        key, sub = jax.random.split(key)
        if isinstance(inner, Discrete):
            flip_key, choice_key = jax.random.split(sub)
            action = jnp.where(jax.random.bernoulli(flip_key, params), inner.sample(choice_key), action)
        else:
            action = action + params * jax.random.normal(sub, inner.shape, inner.dtype)
            action = jnp.clip(action, jnp.asarray(inner.low, inner.dtype), jnp.asarray(inner.high, inner.dtype))
        carry, outcome = inner_step(carry, action)
        return carry, outcome, key

    return ActionTool(step=step, reset=reset, default_params=lambda: jnp.asarray(scale, jnp.float32),
                      name=f"noise({scale})")
