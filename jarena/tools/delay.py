"""``delay``: apply each action a fixed number of steps after the agent chose it."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.core.tool import ActionTool


def delay(steps: int = 1) -> ActionTool:
    """Delays actions by ``steps`` agent steps; the first ``steps`` steps apply the inner no-op (zeros).

    State: a FIFO queue of the last ``steps`` actions, shape (steps, *action_shape).
    """
    steps = int(steps)
    if steps < 0:
        raise ValueError(f"delay needs steps >= 0, got {steps}")

    def reset(key, params, inner):
        return jax.tree_util.tree_map(lambda z: jnp.broadcast_to(z, (steps,) + z.shape), inner.zeros())

    def step(queue, action, carry, inner_step, params, inner):
        if steps == 0:
            applied = action
        else:
            applied = jax.tree_util.tree_map(lambda q: q[0], queue)
            queue = jax.tree_util.tree_map(lambda q, a: jnp.concatenate([q[1:], a[None]]), queue, action)
        carry, outcome = inner_step(carry, applied)
        return carry, outcome, queue

    return ActionTool(step=step, reset=reset, name=f"delay({steps})")
