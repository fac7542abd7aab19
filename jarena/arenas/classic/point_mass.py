"""A point mass on a bounded plane, pushed by a 2-D force (no Gymnasium peer).

- Physics: ``PointMassState`` of float32 ``position`` (2,) (m) and ``velocity`` (2,) (m/s); semi-implicit
  Euler with ``dt = 0.05`` s, mass 1 kg and linear damping 1 N s/m:
  ``velocity += dt (force - damping velocity) / mass``, clipped to ``[-max_speed, max_speed]`` per axis
  (2 m/s; never active at the default params, where the terminal speed is ``max_force / damping`` = 1 m/s),
  then ``position += dt velocity``. The arena is the square ``[-1, 1]^2``: a position leaving it is clipped
  to the wall and the velocity along that axis is zeroed (a perfectly inelastic wall; the other axis
  slides on).
- Control: ``Box(-1, 1, (2,))``, the force (N); values outside are clipped to ``[-max_force, max_force]``.
- Observation: ``{"state": float32 (4,)}`` = (x, y, x_dot, y_dot), bounds ``[-1, 1]^2 x [-2, 2]^2``.
- Task ``reach``: :func:`jarena.tasks.goal_reaching` of the position, goal uniform in ``[-0.8, 0.8]^2``
  per episode (in ``info.goal``); dense reward minus the distance to the goal (``reward="sparse"``: 1 on
  success steps); success while within ``threshold = 0.05`` m; never terminates; 200-step time limit.
- Initial state: position uniform in ``[-0.8, 0.8]^2``, velocity 0.
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
from jarena.render.classic import draw_point_mass
from jarena.tasks.goal_reaching import goal_reaching


@struct.dataclass
class PointMassState:
    position: jax.Array
    velocity: jax.Array


@struct.dataclass
class PointMassParams:
    mass: jax.Array = 1.0
    damping: jax.Array = 1.0
    dt: jax.Array = 0.05
    max_force: jax.Array = 1.0
    max_speed: jax.Array = 2.0
    bound: jax.Array = 1.0  # the arena is [-bound, bound]^2
    init_position: jax.Array = 0.8  # position ~ U[-init_position, init_position]^2
    init_velocity: jax.Array = 0.0  # velocity ~ U[-init_velocity, init_velocity]^2


def init(key, params: PointMassParams) -> PointMassState:
    key_position, key_velocity = jax.random.split(key)
    position = jax.random.uniform(key_position, (2,), jnp.float32, -params.init_position, params.init_position)
    velocity = jax.random.uniform(key_velocity, (2,), jnp.float32, -params.init_velocity, params.init_velocity)
    return PointMassState(position=position, velocity=velocity)


def step(state: PointMassState, control, params: PointMassParams) -> PointMassState:
    force = jnp.clip(control, -params.max_force, params.max_force)
    velocity = state.velocity + params.dt * (force - params.damping * state.velocity) / params.mass
    velocity = jnp.clip(velocity, -params.max_speed, params.max_speed)
    position = state.position + params.dt * velocity
    clipped = jnp.clip(position, -params.bound, params.bound)
    velocity = jnp.where(clipped != position, 0.0, velocity)
    return PointMassState(position=clipped, velocity=velocity)


def observe(state: PointMassState, params) -> dict[str, jax.Array]:
    return {"state": jnp.concatenate([state.position, state.velocity]).astype(jnp.float32)}


_HIGH = np.array([1.0, 1.0, 2.0, 2.0])
OBSERVATION_SPEC = Dict(state=Box(-_HIGH, _HIGH, dtype=jnp.float32))


def reach(threshold: float = 0.05, reward: str = "dense") -> Task:
    """Bring the point to a goal drawn uniformly in ``[-0.8, 0.8]^2`` per episode (see ``goal_reaching``)."""
    return goal_reaching(position=lambda p: p.position, low=[-0.8, -0.8], high=[0.8, 0.8], threshold=threshold,
                         reward=reward)


def dynamics() -> Dynamics:
    return Dynamics(init=init, step=step, control_spec=Box(-1.0, 1.0, (2,), jnp.float32),
                    default_params=lambda: as_float32(PointMassParams()), timestep=0.05, render=draw_point_mass,
                    name="point_mass")


def sensor() -> Sensor:
    return Sensor(observe=observe, spec=OBSERVATION_SPEC, name="point_mass_state")


DOMAIN = Domain(name="point_mass", dynamics=dynamics, sensor=sensor, tasks={"reach": reach}, time_limit=200)
