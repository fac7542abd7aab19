"""``reward_scale``: multiply the reward by a constant."""

from __future__ import annotations

import jax.numpy as jnp

from jarena.core.task import Task


def reward_scale(scale: float) -> Task:
    """Multiplies the reward so far by ``scale`` (float32 param, vmappable). Reward terms stay raw."""

    def update(state, outcome, transition, params):
        return outcome.replace(reward=outcome.reward * params), state

    return Task(update=update, default_params=lambda: jnp.asarray(scale, jnp.float32),
                name=f"reward_scale({scale})")
