"""dm_control ``pendulum``: swingup.

- Physics: MJX on the suite's ``pendulum.xml`` (Euler, 0.02 s; one physics step per control step;
  contacts off).
- Control: ``Box(-1, 1, (1,))``, torque on the hinge.
- Observation: ``orientation`` (2,) = the pole's ``xmat`` zz and xz (cosine and sine of its angle from
  upright); ``velocity`` (1,) = the hinge's angular velocity.
- Reward: 1 while the pole is within 8 degrees of upright (its zz >= cos 8 deg), else 0 (the suite's
  ``tolerance`` with no margin). Success: the same criterion.
- Episodes: 20 s = 1000 steps, no termination; the hinge starts uniform in [-pi, pi), at rest.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 20.0
_CONTROL_TIMESTEP = 0.02  # the model's timestep: control.Environment's default of one physics step
_COSINE_BOUND = float(np.cos(np.deg2rad(8)))


def dynamics() -> Dynamics:
    return common.domain_dynamics("pendulum", 1)


def _pole() -> int:
    return common.names("pendulum").body("pole")


def pole_vertical(data) -> jax.Array:
    return common.xmat_entry(data, _pole(), "zz")


def observe(data, params):
    orientation = jnp.stack([common.xmat_entry(data, _pole(), "zz"), common.xmat_entry(data, _pole(), "xz")])
    return {"orientation": orientation.astype(jnp.float32), "velocity": data.qvel[:1].astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-pendulum")


def upright(data) -> jax.Array:
    """The suite's reward, 0 or 1: ``tolerance(pole_vertical, (cos 8 deg, 1))``."""
    return tolerance(pole_vertical(data), (_COSINE_BOUND, 1.0))


def swingup() -> Task:
    def initialize(key, data, dynamics_params, params):
        return data.replace(qpos=data.qpos.at[0].set(jax.random.uniform(key, (), minval=-jnp.pi, maxval=jnp.pi)))

    def reset(key, data, outcome, params):
        return outcome.replace(success=upright(data) > 0), ()

    def update(state, outcome, transition, params):
        reward = upright(transition.physics)
        return outcome.replace(reward=outcome.reward + reward, success=reward > 0), state

    return Task(update=update, reset=reset, initialize=initialize, name="swingup", has_success=True)


DOMAIN = Domain(name="pendulum", dynamics=dynamics, sensor=sensor, tasks={"swingup": swingup},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={"swingup": ("benchmark",)})
