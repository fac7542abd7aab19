"""dm_control ``ball_in_cup``: catch.

- Physics: MJX on the suite's ``ball_in_cup.xml`` (Euler, 0.002 s; ten physics steps per 0.02 s control
  step): a cup on two sprung, damped slide joints (x, z) and a ball on two slide joints, tied to the
  cup by a 0.3 m string (a limited spatial tendon); contacts between ball, cup and ground.
- Control: ``Box(-1, 1, (2,))``, forces on the cup's x and z joints (gear 5).
- Observation: ``position`` (4,) = qpos (cup x, cup z, ball x, ball z); ``velocity`` (4,) = qvel.
- Reward: 1 while the ball's centre is inside the cup's target box shrunk by the ball's radius (|dx| <
  0.025 m and |dz| < 0.025 m from the target site), else 0. Success: the same criterion.
- Episodes: 20 s = 1000 steps, no termination. The cup starts at rest at its origin, the ball at rest at
  x ~ U[-0.2, 0.2), z ~ U[0.2, 0.5) on its joints, redrawn until it touches nothing (dm_control's
  rejection loop, here at most 1000 draws, keeping the last).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task

_TIME_LIMIT = 20.0
_CONTROL_TIMESTEP = 0.02
_PHYSICS_TIMESTEP = 0.002  # ball_in_cup.xml's (MuJoCo's default)
_XZ = np.array([0, 2])


def dynamics() -> Dynamics:
    return common.domain_dynamics("ball_in_cup", round(_CONTROL_TIMESTEP / _PHYSICS_TIMESTEP))


def observe(data, params):
    return {"position": data.qpos.astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-ball_in_cup")


def ball_to_target(data) -> jax.Array:
    """The target site's minus the ball's (x, z) position (m)."""
    names = common.names("ball_in_cup")
    return data.site_xpos[names.site("target"), _XZ] - data.xpos[names.body("ball"), _XZ]


def in_target(data) -> jax.Array:
    """The suite's ``Physics.in_target`` as a bool."""
    names = common.names("ball_in_cup")
    model = names.model
    half_room = model.site_size[names.site("target"), _XZ] - model.geom_size[names.geom("ball"), 0]
    return jnp.all(jnp.abs(ball_to_target(data)) < jnp.asarray(half_room, jnp.float32))


def catch() -> Task:
    names = common.names("ball_in_cup")
    ball = np.array([names.qpos("ball_x"), names.qpos("ball_z")])
    device_model = common.device_model("ball_in_cup")

    def place_ball(key, data):
        k_x, k_z = jax.random.split(key)
        xz = jnp.stack([jax.random.uniform(k_x, (), minval=-0.2, maxval=0.2),
                        jax.random.uniform(k_z, (), minval=0.2, maxval=0.5)])
        return data.replace(qpos=data.qpos.at[ball].set(xz))

    def initialize(key, data, dynamics_params, params):
        return common.sample_collision_free(key, data, place_ball, device_model)

    def reset(key, data, outcome, params):
        return outcome.replace(success=in_target(data)), ()

    def update(state, outcome, transition, params):
        hit = in_target(transition.physics)
        return outcome.replace(reward=outcome.reward + hit.astype(jnp.float32), success=hit), state

    return Task(update=update, reset=reset, initialize=initialize, name="catch", has_success=True)


DOMAIN = Domain(name="ball_in_cup", dynamics=dynamics, sensor=sensor, tasks={"catch": catch},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={"catch": ("benchmark",)})
