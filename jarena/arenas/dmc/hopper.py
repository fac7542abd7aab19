"""dm_control ``hopper``: stand, hop.

- Physics: MJX on the suite's ``hopper.xml`` (Euler, 0.005 s; 4 physics steps per 0.02 s control step).
- Control: ``Box(-1, 1, (4,))``, torques on the waist, hip, knee and ankle.
- Observation: ``position`` (6,) = qpos without the horizontal root position; ``velocity`` (7,) = qvel;
  ``touch`` (2,) = ``log1p`` of the toe and heel touch sensors (contact normal force in the sensor zone,
  computed by MJX's touch sensor from the last physics step's contact forces, as MuJoCo's).
- Reward: ``standing = tolerance(torso - foot centre-of-mass height, (0.6, 2))`` (1 inside, 0 outside);
  stand: ``standing * (4 + mean(tolerance(ctrl, margin=1, quadratic, value_at_margin=0))) / 5``;
  hop: ``standing * tolerance(torso subtree x velocity, (2, inf), margin=1, linear,
  value_at_margin=0.5)``. Success: none (the suite has no success criterion), always False.
- Episodes: 20 s = 1000 steps. Initial state: ``randomize_limited_and_rotational_joints`` (joints uniform
  in their ranges, the root's pitch uniform in [-pi, pi], root position kept), zero velocity. As in the
  suite (whose hopper, unlike its humanoid, does not re-draw), starts may be in contact: about 17% of
  them, nearly all the leg in the torso (0.2% the floor).
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
_CONTROL_TIMESTEP = 0.02
_STAND_HEIGHT = 0.6
_HOP_SPEED = 2.0


def dynamics() -> Dynamics:
    return common.domain_dynamics("hopper", round(_CONTROL_TIMESTEP / common.load_model("hopper").opt.timestep))


def height(data) -> jax.Array:
    """Height of the torso's centre of mass over the foot's (m)."""
    names = common.names("hopper")
    return data.xipos[names.body("torso"), 2] - data.xipos[names.body("foot"), 2]


def speed(data) -> jax.Array:
    """The torso subtree's (the hopper's centre of mass) forward velocity (m/s)."""
    return data.sensordata[common.names("hopper").sensor("torso_subtreelinvel")][0]


def touch(data) -> jax.Array:
    """``log1p`` of the toe and heel touch sensors (2,)."""
    names = common.names("hopper")
    return jnp.log1p(jnp.concatenate([data.sensordata[names.sensor("touch_toe")],
                                      data.sensordata[names.sensor("touch_heel")]]))


def observe(data, params):
    return {"position": data.qpos[1:].astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32),
            "touch": touch(data).astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-hopper")


def reward(data, hopping: bool) -> jax.Array:
    """The suite's ``Hopper.get_reward`` on the state after a step."""
    standing = tolerance(height(data), (_STAND_HEIGHT, 2.0))
    if hopping:
        return standing * tolerance(speed(data), (_HOP_SPEED, float("inf")), margin=_HOP_SPEED / 2,
                                    value_at_margin=0.5, sigmoid="linear")
    small_control = tolerance(data.ctrl, margin=1, value_at_margin=0, sigmoid="quadratic").mean()
    return standing * (small_control + 4) / 5


def initialize(key, data, dynamics_params, params):
    """The suite's ``Hopper.initialize_episode``: random joints, velocities as reset (zero)."""
    return data.replace(qpos=common.randomize_limited_and_rotational_joints(key, common.load_model("hopper"),
                                                                            data.qpos))


def _hopper(hopping: bool, name: str) -> Task:
    return common.suite_task(name, lambda data: reward(data, hopping), initialize)


def stand() -> Task:
    return _hopper(False, "stand")


def hop() -> Task:
    return _hopper(True, "hop")


DOMAIN = Domain(name="hopper", dynamics=dynamics, sensor=sensor, tasks={"stand": stand, "hop": hop},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("stand", "hop")})
