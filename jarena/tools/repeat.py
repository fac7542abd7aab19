"""``repeat``: action repeat with reward accumulation."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.core.tool import ActionTool
from jarena.core.tree import tree_where


def _accumulate(total, outcome, stopped):
    """Adds ``outcome`` to the running ``total`` unless the episode ``stopped`` earlier in the repeat."""
    live = ~stopped
    add = lambda a, b: a + jnp.where(live, b, jnp.zeros_like(b))
    return total.replace(
        reward=add(total.reward, outcome.reward),
        reward_terms=jax.tree_util.tree_map(add, total.reward_terms, outcome.reward_terms),
        terminated=total.terminated | (live & outcome.terminated),
        truncated=total.truncated | (live & outcome.truncated),
        success=jnp.where(live, outcome.success, total.success),
        goal=jnp.where(live, outcome.goal, total.goal),
        metrics=tree_where(live, outcome.metrics, total.metrics),
    )


def repeat(times: int) -> ActionTool:
    """Applies each action ``times`` low-level steps, summing rewards (and reward terms).

    Stops early when the episode terminates or is truncated inside the repeat: the physics is frozen
    at that step and later rewards are not added. Success, goal and metrics are from the last step run.
    """
    times = int(times)
    if times < 1:
        raise ValueError(f"repeat needs times >= 1, got {times}")

    def step(state, action, carry, inner_step, params, inner):
        carry, total = inner_step(carry, action)

        def body(c, _):
            carry, total = c
            stopped = total.done
            next_carry, outcome = inner_step(carry, action)
            return (tree_where(stopped, carry, next_carry), _accumulate(total, outcome, stopped)), None

        if times > 1:
            (carry, total), _ = jax.lax.scan(body, (carry, total), None, length=times - 1)
        return carry, total, state

    return ActionTool(step=step, substeps=times, name=f"repeat({times})")
