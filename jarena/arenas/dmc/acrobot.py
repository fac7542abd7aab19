"""dm_control ``acrobot``: swingup, swingup_sparse.

- Physics: MJX on the suite's ``acrobot.xml`` (RK4, 0.01 s; one physics step per control step;
  constraints off).
- Control: ``Box(-1, 1, (1,))``, torque on the elbow (gear 2); the shoulder is passive.
- Observation: ``orientations`` (4,) = ``xmat`` xz of the upper and lower arm, then their zz (sines
  and cosines of the arms' angles from upright); ``velocity`` (2,) = qvel (shoulder, elbow).
- Reward: ``tolerance(d, (0, 0.2), margin=1)`` of the distance d from the tip to the target site 4 m
  above the ground (gaussian, 0.1 at the margin); sparse: 1 when d <= 0.2 (the target's radius).
  Success (both tasks): d <= 0.2.
- Episodes: 10 s = 1000 steps, no termination; shoulder and elbow start uniform in [-pi, pi), at rest.
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

_TIME_LIMIT = 10.0
_CONTROL_TIMESTEP = 0.01  # the model's timestep: control.Environment's default of one physics step


def dynamics() -> Dynamics:
    return common.domain_dynamics("acrobot", 1)


def _arms() -> np.ndarray:
    names = common.names("acrobot")
    return np.array([names.body("upper_arm"), names.body("lower_arm")])


def observe(data, params):
    arms = _arms()
    orientations = jnp.concatenate([common.xmat_entry(data, arms, "xz"), common.xmat_entry(data, arms, "zz")])
    return {"orientations": orientations.astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-acrobot")


def target_radius() -> float:
    """``site_size['target', 0]`` of the model (0.2 m)."""
    names = common.names("acrobot")
    return float(names.model.site_size[names.site("target"), 0])


def to_target(data) -> jax.Array:
    """Distance (m) from the tip to the target's centre."""
    names = common.names("acrobot")
    return jnp.linalg.norm(data.site_xpos[names.site("target")] - data.site_xpos[names.site("tip")])


def reward(data, sparse: bool) -> jax.Array:
    """The suite's ``Balance._get_reward`` on the state after a step."""
    return tolerance(to_target(data), bounds=(0.0, target_radius()), margin=0.0 if sparse else 1.0)


def _success(data) -> jax.Array:
    return to_target(data) <= target_radius()


def _balance(sparse: bool, name: str) -> Task:
    def initialize(key, data, dynamics_params, params):
        names = common.names("acrobot")
        joints = np.array([names.qpos("shoulder"), names.qpos("elbow")])
        return data.replace(qpos=data.qpos.at[joints].set(jax.random.uniform(key, (2,), minval=-jnp.pi,
                                                                             maxval=jnp.pi)))

    return common.suite_task(name, lambda data: reward(data, sparse), initialize, success=_success)


def swingup() -> Task:
    return _balance(False, "swingup")


def swingup_sparse() -> Task:
    return _balance(True, "swingup_sparse")


DOMAIN = Domain(name="acrobot", dynamics=dynamics, sensor=sensor,
                tasks={"swingup": swingup, "swingup_sparse": swingup_sparse},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("swingup", "swingup_sparse")})
