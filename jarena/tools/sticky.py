"""``sticky``: sticky actions (as in the Arcade Learning Environment's ``repeat_action_probability``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.tool import ActionTool
from jarena.core.tree import tree_where


@struct.dataclass
class StickyState:
    """key: PRNG key; previous: last applied action; started: whether an action was applied yet."""

    key: jax.Array
    previous: jax.Array
    started: jax.Array


def sticky(probability: float = 0.25) -> ActionTool:
    """With probability ``probability`` (float32 param) applies the previous action instead of the new.

    The first step of an episode always applies the new action.
    """
    if not 0.0 <= probability <= 1.0:
        raise ValueError(f"sticky needs 0 <= probability <= 1, got {probability}")

    def reset(key, params, inner):
        return StickyState(key=key, previous=inner.zeros(), started=jnp.zeros((), bool))

    def step(state, action, carry, inner_step, params, inner):
        key, sub = jax.random.split(state.key)
        keep = state.started & jax.random.bernoulli(sub, params)
        applied = tree_where(keep, state.previous, action)
        carry, outcome = inner_step(carry, applied)
        return carry, outcome, StickyState(key=key, previous=applied, started=jnp.ones((), bool))

    return ActionTool(step=step, reset=reset, default_params=lambda: jnp.asarray(probability, jnp.float32),
                      name=f"sticky({probability})")
