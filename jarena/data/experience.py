"""``Experience``: one stored transition, built from the infos around an agent step.

A transition from jarena is made of the observation the agent acted on, its action, and what the
step returned. After an auto-reset the info after the step shows the *new* episode, so the next
observation comes from ``info.final`` (the finished episode's terminal observation), which is always
the right one.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.arena import Arena
from jarena.core.types import Info

Array = jax.Array
PyTree = Any


@struct.dataclass
class Experience:
    """One transition (shapes for one arena; buffers and batches add leading axes).

    Attributes:
      observation: dict of arrays, the observation the agent acted on.
      action: the action taken (any pytree, as ``arena.action_spec``).
      reward: float32 scalar, the reward of this step.
      terminated: bool scalar; the episode ended with this step, in a terminal state.
      truncated: bool scalar; the episode was cut short with this step (time limit).
      success: bool scalar; the task's success criterion after this step.
      next_observation: dict of arrays, the observation this step reached (the terminal one at an
        episode's end, even under auto-reset).
      goal: float32 (goal_dim,), the episode's goal.
      episode: int32 episode id.
      step: int32 index of this transition in its episode (0 for the first action after reset).
    """

    observation: dict[str, Array]
    action: PyTree
    reward: Array
    terminated: Array
    truncated: Array
    success: Array
    next_observation: dict[str, Array]
    goal: Array
    episode: Array
    step: Array

    @property
    def done(self) -> Array:
        """``terminated | truncated``: the episode ended with this transition."""
        return self.terminated | self.truncated


def transition_from(info_before: Info, action: PyTree, info_after: Info) -> Experience:
    """The transition from ``info_before`` through ``action`` to ``info_after`` (any batch shape).

    Works with or without auto-reset: episode id, step and goal come from ``info_before`` and the
    next observation from ``info_after.final``.
    """
    return Experience(observation=info_before.observation, action=action, reward=info_after.reward,
                      terminated=info_after.terminated, truncated=info_after.truncated,
                      success=info_after.success, next_observation=info_after.final.observation,
                      goal=info_before.goal, episode=info_before.episode, step=info_before.step)


def experience_spec(arena: Arena) -> Experience:
    """The shapes and dtypes of one :class:`Experience` of ``arena`` (``jax.ShapeDtypeStruct`` leaves).

    Pass it to ``buffer.init`` to allocate a buffer without running the arena.
    """

    def one():
        state, info = arena.reset(jax.random.key(0))
        action = arena.no_op()
        _, after = arena.step(state, action)
        return transition_from(info, jax.tree_util.tree_map(jnp.asarray, action), after)

    return jax.eval_shape(one)
