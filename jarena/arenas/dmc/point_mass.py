"""dm_control ``point_mass``: easy.

- Physics: MJX on the suite's ``point_mass.xml`` (Euler, 0.02 s; one physics step per control step;
  contacts off): a 0.3 kg mass on two damped slide joints limited to +-0.29 m.
- Control: ``Box(-1, 1, (2,))``, forces along x and y (through two fixed tendons, gear 0.1).
- Observation: ``position`` (2,) = qpos; ``velocity`` (2,) = qvel.
- Reward: ``near_target * small_control``: ``near_target = tolerance(d, (0, r), margin=r)`` of the
  distance d from the mass to the target (r = 0.015 m, its radius) and ``small_control = (4 + mean
  tolerance(control, margin=1, quadratic, 0 at the margin)) / 5``. Success: d <= r.
- Episodes: 20 s = 1000 steps, no termination; both joints start uniform in their range, at rest.
  (The suite's ``hard`` task, which randomises the actuators' directions per episode, is not ported.)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 20.0
_CONTROL_TIMESTEP = 0.02  # the model's timestep: control.Environment's default of one physics step


def dynamics() -> Dynamics:
    return common.domain_dynamics("point_mass", 1)


def observe(data, params):
    return {"position": data.qpos.astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-point_mass")


def target_size() -> float:
    """``geom_size['target', 0]`` of the model (0.015 m)."""
    names = common.names("point_mass")
    return float(names.model.geom_size[names.geom("target"), 0])


def mass_to_target_dist(data) -> jax.Array:
    names = common.names("point_mass")
    return jnp.linalg.norm(data.geom_xpos[names.geom("target")] - data.geom_xpos[names.geom("pointmass")])


def reward(data) -> jax.Array:
    """The suite's ``PointMass.get_reward`` on the state after a step (control from ``data.ctrl``)."""
    size = target_size()
    near_target = tolerance(mass_to_target_dist(data), bounds=(0.0, size), margin=size)
    control_reward = tolerance(data.ctrl, margin=1, value_at_margin=0, sigmoid="quadratic").mean()
    return near_target * (control_reward + 4) / 5


def _success(data) -> jax.Array:
    return mass_to_target_dist(data) <= target_size()


def easy() -> Task:
    def initialize(key, data, dynamics_params, params):
        qpos = common.randomize_limited_and_rotational_joints(key, common.load_model("point_mass"), data.qpos)
        return data.replace(qpos=qpos)

    return common.suite_task("easy", reward, initialize, success=_success)


DOMAIN = Domain(name="point_mass", dynamics=dynamics, sensor=sensor, tasks={"easy": easy},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={"easy": ("benchmark",)})
