"""``time_limit``: truncate episodes after a number of dynamics steps."""

from __future__ import annotations

import jax.numpy as jnp

from jarena.core.task import Task


def time_limit(max_steps: int) -> Task:
    """Truncates the episode once ``max_steps`` dynamics steps have run (as Gymnasium's ``TimeLimit``).

    Counts low-level steps (physical time, as dm_control): with ``repeat(k)`` an episode has
    ``ceil(max_steps / k)`` agent steps. State: int32 step counter. Params: int32 ``max_steps``
    (vmappable; it must not exceed the static ``max_steps`` that sizes runners' loops).
    """
    if int(max_steps) < 1:
        raise ValueError(f"time_limit needs max_steps >= 1, got {max_steps}")

    def reset(key, physics, outcome, params):
        return outcome, jnp.zeros((), jnp.int32)

    def update(count, outcome, transition, params):
        count = count + 1
        return outcome.replace(truncated=outcome.truncated | (count >= params)), count

    return Task(update=update, reset=reset, default_params=lambda: jnp.asarray(int(max_steps), jnp.int32),
                horizon=int(max_steps), name=f"time_limit({max_steps})")
