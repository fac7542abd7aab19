"""A host simulator's pieces as jarena dynamics, sensor and task: the state is a handle, the steps host calls.

- Physics state :class:`HostPhysics`: which batch and slot of the :class:`~jarena.arenas.host.pool.EnvPool`
  holds the arena's simulator, and what its last step returned (observation, reward, flags).
- ``init(key, params)`` opens a batch (under ``vmap``, one host call for the B arenas) and resets each
  simulator with :func:`seed_of` its key; ``step`` steps the batch's vector env once; ``restart`` (the
  ``host`` auto-reset) resets the simulators whose episode ended with the next episode's seed.
- Sensor: the simulator's observation, ``{"state": ...}`` (or the keys of a dict observation).
- Task ``host``: the simulator's reward, ``terminated`` and ``truncated``.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.arenas.host.calls import batched_host_call
from jarena.arenas.host.pool import EnvPool
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.episodes import piece_key
from jarena.core.spec import Dict, Spec
from jarena.core.task import Task

PyTree = Any


@struct.dataclass
class HostPhysics:
    """One arena's handle on its host simulator and the simulator's last step.

    Attributes:
      batch: int32, the pool batch (one ``batch_reset``) that holds the simulator.
      slot: int32, the simulator's index in its batch's vector env.
      observation: dict of arrays, the simulator's last observation.
      reward: float32, the last step's reward (0 after a reset).
      terminated: bool, the last step's terminated flag.
      truncated: bool, the last step's truncated flag.
    """

    batch: jax.Array
    slot: jax.Array
    observation: dict[str, jax.Array]
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array


def seed_of(key: jax.Array) -> jax.Array:
    """The simulator seed (int32 in ``[0, 2^31)``) of an episode's dynamics key."""
    return (jax.random.bits(key, (), jnp.uint32) >> 1).astype(jnp.int32)


def episode_seed(episode: int) -> int:
    """The seed a host arena's simulator is reset with for jarena episode ``episode``: evaluation episode 3 of
    ``gym|id:CartPole-v1`` is ``gymnasium.make("CartPole-v1").reset(seed=episode_seed(3))``."""
    return int(seed_of(piece_key(jnp.asarray(episode, jnp.int32), 0)))


def _structs(spec: Dict, size: int) -> dict[str, jax.ShapeDtypeStruct]:
    return {k: jax.ShapeDtypeStruct((size,) + s.shape, s.dtype) for k, s in spec.spaces.items()}


def host_dynamics(pool: EnvPool, observation: Dict, control: Spec, name: str = "host") -> Dynamics:
    """Dynamics stepping ``pool``'s simulators, whose observations have ``observation``'s spec and whose
    controls have ``control``'s (a ``Box`` or ``Discrete``). No params: a host simulator's constants are
    its own.

    Each host call costs a fixed overhead plus a little per array that crosses (about 28 + 8 us per array on
    a CPU), so the calls pack what they can: ids, seeds and masks into one int32 array, reward and flags into
    one float32 array."""
    start = batched_host_call(
        pool.start, lambda size: (jax.ShapeDtypeStruct((size, 2), jnp.int32), _structs(observation, size)))
    step_call = batched_host_call(
        lambda handle, action: pool.step(handle[:, 0], handle[:, 1], action),
        lambda size: (_structs(observation, size), jax.ShapeDtypeStruct((size, 3), jnp.float32)))
    restart_call = batched_host_call(
        lambda packed: pool.restart(packed[:, 0], packed[:, 1], packed[:, 2], packed[:, 3].astype(bool)),
        lambda size: _structs(observation, size))
    no = jnp.zeros((), bool)

    def init(key, params):
        handle, obs = start(seed_of(key))
        return HostPhysics(batch=handle[0], slot=handle[1], observation=obs, reward=jnp.zeros((), jnp.float32),
                           terminated=no, truncated=no)

    def step(physics: HostPhysics, action, params):
        obs, outcome = step_call(jnp.stack([physics.batch, physics.slot]), jnp.asarray(action))
        return physics.replace(observation=obs, reward=outcome[0], terminated=outcome[1] > 0,
                               truncated=outcome[2] > 0)

    def restart(physics: HostPhysics, key, done, params):
        packed = jnp.stack([physics.batch, physics.slot, seed_of(key), jnp.asarray(done, jnp.int32)])
        obs = restart_call(packed)
        return physics.replace(observation=obs, reward=jnp.zeros((), jnp.float32), terminated=no, truncated=no)

    return Dynamics(init=init, step=step, control_spec=control, restart=restart, name=name)


def host_sensor(observation: Dict, name: str = "host") -> Sensor:
    """The simulator's observation as it came, with its spec."""
    return Sensor(observe=lambda physics, params: dict(physics.observation), spec=observation, name=name)


def host_task(horizon: int | None = None) -> Task:
    """The simulator's reward and flags (a simulator's own time limit truncates). ``horizon``: the simulator's
    longest episode in steps, when it has one, for runners that size their loops."""

    def update(state, outcome, transition, params):
        physics = transition.physics
        return outcome.replace(reward=outcome.reward + physics.reward,
                               terminated=outcome.terminated | physics.terminated,
                               truncated=outcome.truncated | physics.truncated), state

    return Task(update=update, horizon=horizon, name="host")
