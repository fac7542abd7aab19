"""Dynamics and sensors: the physics of an arena and what an agent can observe of it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from jarena.core import faults
from jarena.core.spec import Spec

PyTree = Any


def _no_params() -> tuple:
    return ()


@dataclasses.dataclass(frozen=True)
class Dynamics:
    """A frozen bundle of pure physics functions.

    Attributes:
      init: ``(key, params) -> physics``, a random initial physics state.
      step: ``(physics, control, params) -> physics``, one low-level step of ``timestep`` seconds.
      control_spec: spec of the control accepted by ``step``.
      default_params: ``() -> params``; physical constants live here so users can vmap over them.
      no_op: ``() -> control`` that applies no actuation (defaults to the spec's zeros; set it for
        discrete controls where index 0 actuates).
      timestep: seconds of simulated time per ``step``.
      render: optional host-side ``(physics, params, **kwargs) -> uint8 image (H, W, 3)``.
      name: a short name for messages.
      after_reset: optional ``(physics, params) -> physics`` run after the task placed the initial state
        (see ``Task.initialize``) to recompute derived quantities, as MuJoCo's ``mj_forward``.
      finite: optional ``physics -> bool scalar``, whether the physics state is finite, checked by
        ``Arena.step`` after every step (see :meth:`is_finite`); set it to check a few essential arrays
        (MJX: ``qpos``, ``qvel``, ``act``) instead of every floating leaf of a large state.
      restart: for dynamics whose simulator lives outside JAX (host arenas, :mod:`jarena.arenas.host`), where
        ``physics`` is a handle on it: ``(physics, key, done, params) -> physics`` starts a new episode,
        seeded by ``key``, in the simulator where ``done`` (bool scalar) and keeps the others. Such dynamics
        run under the ``host`` auto-reset strategy only (:mod:`jarena.core.resets`), and their states
        cannot be copied or rolled forward by planners.
    """

    init: Callable[[jax.Array, PyTree], PyTree]
    step: Callable[[PyTree, PyTree, PyTree], PyTree]
    control_spec: Spec
    default_params: Callable[[], PyTree] = _no_params
    no_op: Callable[[], PyTree] | None = None
    timestep: float = 1.0
    render: Callable[..., Any] | None = None
    name: str = "dynamics"
    after_reset: Callable[[PyTree, PyTree], PyTree] | None = None
    finite: Callable[[PyTree], jax.Array] | None = None
    restart: Callable[[PyTree, jax.Array, jax.Array, PyTree], PyTree] | None = None

    @property
    def on_host(self) -> bool:
        """Whether the simulator lives outside JAX (``restart`` is set): states are handles, not values."""
        return self.restart is not None

    def no_op_control(self) -> PyTree:
        return self.no_op() if self.no_op is not None else self.control_spec.zeros()

    def is_finite(self, physics: PyTree) -> jax.Array:
        """bool scalar: ``physics`` holds no NaN or infinity (``finite``, or else every floating leaf)."""
        if self.finite is not None:
            return jnp.asarray(self.finite(physics), bool)
        return faults.all_finite(physics)


@dataclasses.dataclass(frozen=True)
class SensorMemory:
    """What a sensor remembers from one agent step to the next (e.g. the last frames of a frame stack).

    Attributes:
      start: ``(observation) -> (memory, observation)`` at reset, from the first observation of an episode.
      advance: ``(memory, observation) -> (memory, observation)`` after each agent step.
    Both take the sensor's ``observe`` output and return what the agent sees; ``memory`` is a pytree of
    arrays whose shapes do not change, kept in ``ArenaState.sensor``.
    """

    start: Callable[[dict[str, jax.Array]], tuple[PyTree, dict[str, jax.Array]]]
    advance: Callable[[PyTree, dict[str, jax.Array]], tuple[PyTree, dict[str, jax.Array]]]


@dataclasses.dataclass(frozen=True)
class Sensor:
    """What the agent observes of the physics.

    Attributes:
      observe: ``(physics, params) -> dict[str, array]``.
      spec: a :class:`~jarena.core.spec.Dict` spec of the observation the agent sees (after ``memory``)
        with real bounds, or ``None`` to derive an unbounded spec from the observation's shapes.
      default_params: ``() -> params`` (noise scales, camera settings...).
      name: a short name for messages.
      memory: optional :class:`SensorMemory` for observations that depend on earlier steps (frame stacks);
        it runs once per agent step, after ``observe``.
    """

    observe: Callable[[PyTree, PyTree], dict[str, jax.Array]]
    spec: Spec | None = None
    default_params: Callable[[], PyTree] = _no_params
    name: str = "sensor"
    memory: SensorMemory | None = None
