"""Typed pytrees that flow through an arena: transitions, task outcomes, information and state.

All are frozen ``flax.struct`` dataclasses, so they are pytrees (``vmap``/``scan``/``jit`` apply) and
``.replace(...)`` returns an updated copy. Shapes below are for one arena; batching adds leading axes.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

Array = jax.Array
PyTree = Any


@struct.dataclass
class Transition:
    """One low-level dynamics step, as a task sees it.

    Attributes:
      previous: physics state before the step.
      control: the low-level control applied (after the action tool), in the dynamics' control spec.
      physics: physics state after the step.
      dynamics_params: the dynamics' params (read-only for tasks: e.g. a torque limit that the reward
        must agree with under domain randomisation).
    """

    previous: PyTree
    control: PyTree
    physics: PyTree
    dynamics_params: PyTree = None


@struct.dataclass
class Outcome:
    """What a task reports for one step; threaded through a chain of task transforms.

    Each transform reads the typed fields left by the transforms before it and may overwrite them, or
    add its own named entries to ``reward_terms`` and ``metrics`` (which it never reads back).

    Attributes:
      reward: float32 scalar.
      reward_terms: named float32 scalars that explain the reward (write-only for transforms).
      terminated: bool scalar; the episode reached a terminal state of the task (no bootstrapping).
      truncated: bool scalar; the episode was cut short (time limit), bootstrapping is valid.
      success: bool scalar; the task's success criterion holds at this step.
      goal: float32 vector of shape (goal_dim,), (0,) for tasks without a goal.
      metrics: named scalars for evaluation (write-only for transforms).
    """

    reward: Array
    terminated: Array
    truncated: Array
    success: Array
    goal: Array
    reward_terms: dict[str, Array] = struct.field(default_factory=dict)
    metrics: dict[str, Array] = struct.field(default_factory=dict)

    @classmethod
    def empty(cls) -> Outcome:
        return cls(reward=jnp.zeros((), jnp.float32), terminated=jnp.zeros((), bool),
                   truncated=jnp.zeros((), bool), success=jnp.zeros((), bool), goal=jnp.zeros((0,), jnp.float32))

    @property
    def done(self) -> Array:
        return self.terminated | self.truncated


@struct.dataclass
class Final:
    """Where this step's reward belongs: the episode that the step ran in.

    Equal to the info's own observation, goal, step and episode, except after an auto-reset (see
    :func:`jarena.auto_reset`), where the info shows the new episode and ``final`` keeps the finished
    one. ``final.observation`` is therefore always the right "next observation" of a transition.

    Attributes:
      observation: the observation reached by this step in that episode (terminal one at its end).
      goal: that episode's goal.
      step: int32 agent steps of that episode so far (its length at its end).
      episode: int32 id of that episode.
    """

    observation: dict[str, Array]
    goal: Array
    step: Array
    episode: Array


@struct.dataclass
class Info:
    """What an agent receives from an arena after ``reset`` or ``step``.

    Attributes:
      observation: dict of arrays, as described by ``arena.observation_spec``.
      reward: float32 scalar, reward of the last step (0 after reset).
      reward_terms: dict of named float32 scalars explaining the reward.
      terminated: bool scalar; the episode reached a terminal state (see :class:`Outcome`).
      truncated: bool scalar; the episode was cut short, e.g. by a time limit (see :class:`Outcome`).
      success: bool scalar; the task's success criterion holds (see :class:`Outcome`).
      goal: float32 vector (goal_dim,), (0,) when the task has no goal.
      metrics: dict of named scalars for evaluation.
      step: int32, agent steps taken in this episode.
      episode: int32 episode id (see ``arena.episodes``).
      final: the episode this step belongs to (:class:`Final`); differs from the fields above only
        where :func:`jarena.auto_reset` started a new episode.
      fault: int32 bitmask of what went wrong in this step, 0 for none (always 0 after reset); bits
        and names in :mod:`jarena.core.faults` (``faults.describe(info.fault)``). A faulted step is
        terminated, with reward 0 and the non-finite entries of its observation set to 0 (see
        ``Arena.step``). Like ``terminated``, it stays the finished step's after an auto-reset.
    """

    observation: dict[str, Array]
    reward: Array
    terminated: Array
    truncated: Array
    success: Array
    goal: Array
    step: Array
    episode: Array
    reward_terms: dict[str, Array] = struct.field(default_factory=dict)
    metrics: dict[str, Array] = struct.field(default_factory=dict)
    final: Final | None = None  # always set by Arena.reset / Arena.step / auto_reset
    fault: Array = struct.field(default_factory=lambda: jnp.zeros((), jnp.int32))

    @property
    def done(self) -> Array:
        """``terminated | truncated``."""
        return self.terminated | self.truncated

    @property
    def faulted(self) -> Array:
        """bool: the step faulted (``fault != 0``); such a step is also ``terminated``."""
        return self.fault != 0


@struct.dataclass
class KeyWords:
    """A PRNG key kept as separate uint32 words, so that a batch of keys is a few (B,) arrays, not one (B, 2).

    XLA fuses (B,)-shaped state updates into one kernel; a (B, 2) key array gets its own select/concatenate
    kernel and a copy every step.
    """

    words: tuple
    impl: str = struct.field(pytree_node=False, default="threefry2x32")

    @classmethod
    def pack(cls, key: Array) -> KeyWords:
        """Packs a typed key, or a raw uint32 key (``jax.random.PRNGKey``) of the default implementation."""
        if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
            key = jax.random.wrap_key_data(key)
        data = jax.random.key_data(key)
        return cls(words=tuple(data[..., i] for i in range(data.shape[-1])), impl=str(jax.random.key_impl(key)))

    def unpack(self) -> Array:
        return jax.random.wrap_key_data(jnp.stack(self.words, axis=-1), impl=self.impl)


@struct.dataclass
class ArenaState:
    """The full state of one arena; immutable.

    Attributes:
      physics: the dynamics' state pytree.
      task: the task chain's state (a tuple with one slot per transform).
      tool: the action-tool chain's state (a tuple with one slot per transform).
      step: int32, agent steps taken in this episode.
      episode: int32 episode id.
      rng: :class:`KeyWords`, the PRNG key (``rng.unpack()``) that seeds the next episode when the arena
        auto-resets.
      start: ``None``, or with ``Arena.auto_reset == "repeat"`` the ``(state, info)`` this arena's first
        episode started from (its own ``start`` ``None``), restored when an episode ends.
      sensor: the sensor's memory (``Sensor.memory``, e.g. a frame stack's last frames), ``()`` without one.
    """

    physics: PyTree
    task: PyTree
    tool: PyTree
    step: Array
    episode: Array
    rng: KeyWords
    start: PyTree = None
    sensor: PyTree = ()


@struct.dataclass
class ArenaParams:
    """Parameters of an arena's pieces; vmap over any leaf (masses, goals, time limits...)."""

    dynamics: PyTree
    sensor: PyTree
    task: PyTree
    tool: PyTree
