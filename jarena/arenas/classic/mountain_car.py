"""Mountain car with a continuous action, matching Gymnasium's ``MountainCarContinuous-v0`` (Moore, 1990).

- Physics: ``MountainCarState`` of float32 scalars ``position`` and ``velocity``, in Gymnasium's units
  (one step is one unit of time): ``velocity += power * force - 0.0025 cos(3 position)`` clipped to
  ``[-0.07, 0.07]``, then ``position += velocity`` clipped to ``[-1.2, 0.6]``; at the left wall a
  negative velocity is zeroed.
- Control: ``Box(-1, 1, (1,))``, the force; values outside are clipped for the dynamics (not the reward).
- Observation: ``{"state": float32 (2,)}`` = (position, velocity), bounds ``[-1.2, 0.6] x [-0.07, 0.07]``.
- Task ``continuous``: reward ``-0.1 action^2`` of the raw (unclipped) action every step, plus 100 on the
  step that reaches the goal; terminated when ``position >= 0.45`` and ``velocity >= 0``; success when
  the goal is reached; 999-step time limit.
- Initial state: position uniform in [-0.6, -0.4], velocity 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.spec import Box, Dict
from jarena.core.task import Task
from jarena.core.tree import as_float32
from jarena.render.classic import draw_mountain_car


@struct.dataclass
class MountainCarState:
    position: jax.Array
    velocity: jax.Array


@struct.dataclass
class MountainCarParams:
    min_action: jax.Array = -1.0
    max_action: jax.Array = 1.0
    min_position: jax.Array = -1.2
    max_position: jax.Array = 0.6
    max_speed: jax.Array = 0.07
    power: jax.Array = 0.0015
    gravity: jax.Array = 0.0025  # the hill's pull: -gravity * cos(3 position)
    init_low: jax.Array = -0.6
    init_high: jax.Array = -0.4


@struct.dataclass
class ContinuousParams:
    goal_position: jax.Array = 0.45
    goal_velocity: jax.Array = 0.0
    goal_reward: jax.Array = 100.0
    action_cost: jax.Array = 0.1


def init(key, params: MountainCarParams) -> MountainCarState:
    position = jax.random.uniform(key, (), jnp.float32, params.init_low, params.init_high)
    return MountainCarState(position=position, velocity=jnp.zeros((), jnp.float32))


def step(state: MountainCarState, control, params: MountainCarParams) -> MountainCarState:
    force = jnp.clip(control[0], params.min_action, params.max_action)
    velocity = state.velocity + force * params.power - params.gravity * jnp.cos(3 * state.position)
    velocity = jnp.clip(velocity, -params.max_speed, params.max_speed)
    position = jnp.clip(state.position + velocity, params.min_position, params.max_position)
    velocity = jnp.where((position == params.min_position) & (velocity < 0), 0.0, velocity)
    return MountainCarState(position=position, velocity=velocity)


def observe(state: MountainCarState, params) -> dict[str, jax.Array]:
    return {"state": jnp.stack([state.position, state.velocity]).astype(jnp.float32)}


OBSERVATION_SPEC = Dict(state=Box(np.array([-1.2, -0.07], np.float32), np.array([0.6, 0.07], np.float32),
                                  dtype=jnp.float32))


def continuous() -> Task:
    """Drive up the right hill with little effort (Gymnasium's reward and termination)."""

    def reached(physics, params):
        return (physics.position >= params.goal_position) & (physics.velocity >= params.goal_velocity)

    def reset(key, physics, outcome, params):
        return outcome.replace(success=reached(physics, params)), ()

    def update(state, outcome, transition, params):
        done = reached(transition.physics, params)
        reward = jnp.where(done, params.goal_reward, 0.0) - params.action_cost * transition.control[0] ** 2
        return outcome.replace(reward=outcome.reward + reward, terminated=outcome.terminated | done,
                               success=done), state

    return Task(update=update, reset=reset, default_params=lambda: as_float32(ContinuousParams()),
                name="continuous", has_success=True)


def dynamics() -> Dynamics:
    return Dynamics(init=init, step=step, control_spec=Box(-1.0, 1.0, (1,), jnp.float32),
                    default_params=lambda: as_float32(MountainCarParams()), timestep=1.0, render=draw_mountain_car,
                    name="mountain_car")


def sensor() -> Sensor:
    return Sensor(observe=observe, spec=OBSERVATION_SPEC, name="mountain_car_state")


DOMAIN = Domain(name="mountain_car", dynamics=dynamics, sensor=sensor, tasks={"continuous": continuous},
                time_limit=999, tags={"continuous": ("benchmark",)})
