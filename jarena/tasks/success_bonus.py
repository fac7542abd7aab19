"""``success_bonus``: add a bonus to the reward on steps where the task succeeds."""

from __future__ import annotations

import jax.numpy as jnp

from jarena.core.task import Task


def success_bonus(bonus: float = 1.0, terminate: bool = False) -> Task:
    """Adds ``bonus`` (float32 param) to the reward where ``outcome.success``; reward term ``success_bonus``.

    Args:
      bonus: reward added on each successful step.
      terminate: also terminate the episode on success (static).
    """

    def reset(key, physics, outcome, params):
        terms = dict(outcome.reward_terms, success_bonus=jnp.zeros((), jnp.float32))
        return outcome.replace(reward_terms=terms), ()

    def update(state, outcome, transition, params):
        extra = jnp.where(outcome.success, params, 0.0).astype(jnp.float32)
        terms = dict(outcome.reward_terms, success_bonus=extra)
        terminated = outcome.terminated | outcome.success if terminate else outcome.terminated
        return outcome.replace(reward=outcome.reward + extra, reward_terms=terms, terminated=terminated), state

    return Task(update=update, reset=reset, default_params=lambda: jnp.asarray(bonus, jnp.float32),
                name=f"success_bonus({bonus})")
