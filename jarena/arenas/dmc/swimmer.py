"""dm_control ``swimmer``: swimmer6 (a 6-link swimmer reaching a target).

- Physics: MJX on the suite's generated 6-link ``swimmer.xml`` (Euler, 0.002 s; 15 physics steps per
  0.03 s control step; fluid drag from ``density``; contacts disabled by the model's ``contact`` flag).
  Two edits that leave the dynamics unchanged (tests step MuJoCo on both models to equal states):
  every geom gets ``contype = conaffinity = 0`` (MuJoCo never collides them anyway: the suite's model
  disables contacts; MJX, which builds its collision table from these bits, cannot collide the head's
  ellipsoid with the segments' inertial boxes), and the target is a mocap body (with its light), so its
  per-episode position is ``data.mocap_pos[0]`` in the physics state.
- Control: ``Box(-1, 1, (5,))``, torques on the 5 joints between the links.
- Observation: ``joints`` (5,) = joint angles; ``to_target`` (2,) = target minus nose position in the
  head frame (x, y); ``body_velocities`` (18,) = local x, y velocity and z angular velocity of the head
  and every segment (the model's velocimeters and gyros, ``sensordata[12:]`` as the suite reads it).
- Reward: ``tolerance(|nose to target|, (0, 0.1), margin=0.5, long_tail)`` (0.1 = the target's radius).
  Success: none (the suite's episodes go on after the target is reached), always False.
- Episodes: 30 s = 1000 steps. Initial state: ``randomize_limited_and_rotational_joints`` (heading uniform
  in [-pi, pi], joints uniform in +-60 degrees, position kept), zero velocity; the target uniform in
  [-0.3, 0.3]^2 with probability 0.2, else in [-2, 2]^2 (height 0.05).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 30.0
_CONTROL_TIMESTEP = 0.03
_N_LINKS = 6
_CLOSE_TARGET_PROBABILITY = 0.2


def mjx_xml(xml: str) -> str:
    """The suite's swimmer XML made MJX-ready: no geom in the collision table, the target (and its light)
    a mocap body."""
    return common.without_collisions_target_as_mocap(xml, carried=("light[@name='target_light']",))


def model():
    return common.load_model("swimmer", _N_LINKS, edit=mjx_xml)


def dynamics() -> Dynamics:
    return common.domain_dynamics("swimmer", round(_CONTROL_TIMESTEP / model().opt.timestep), _N_LINKS, edit=mjx_xml)


def _names():
    return common.names("swimmer", _N_LINKS, edit=mjx_xml)


def nose_to_target(data) -> jax.Array:
    """Target minus nose position in the head's frame, x and y (2,)."""
    names = _names()
    to_target = data.geom_xpos[names.geom("target")] - data.geom_xpos[names.geom("nose")]
    return (to_target @ data.xmat[names.body("head")])[:2]


def body_velocities(data) -> jax.Array:
    """Local x, y velocity and z angular velocity of the head and every segment (3 * links,)."""
    return data.sensordata[12:].reshape(-1, 6)[:, jnp.array([0, 1, 5])].ravel()


def observe(data, params):
    return {"joints": data.qpos[3:].astype(jnp.float32), "to_target": nose_to_target(data).astype(jnp.float32),
            "body_velocities": body_velocities(data).astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-swimmer")


def reward(data) -> jax.Array:
    target_size = float(model().geom_size[_names().geom("target"), 0])
    return tolerance(jnp.linalg.norm(nose_to_target(data)), (0.0, target_size), margin=5 * target_size,
                     sigmoid="long_tail")


def initialize(key, data, dynamics_params, params):
    """The suite's ``Swimmer.initialize_episode``: random joints and heading, random target."""
    k_joints, k_close, k_target = jax.random.split(key, 3)
    qpos = common.randomize_limited_and_rotational_joints(k_joints, model(), data.qpos)
    box = jnp.where(jax.random.uniform(k_close) < _CLOSE_TARGET_PROBABILITY, 0.3, 2.0)
    xy = jax.random.uniform(k_target, (2,), minval=-1.0, maxval=1.0) * box
    mocap_pos = data.mocap_pos.at[0, :2].set(xy.astype(data.mocap_pos.dtype))
    return data.replace(qpos=qpos, mocap_pos=mocap_pos)


def swimmer6() -> Task:
    return common.suite_task("swimmer6", reward, initialize)


DOMAIN = Domain(name="swimmer", dynamics=dynamics, sensor=sensor, tasks={"swimmer6": swimmer6},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={"swimmer6": ("benchmark",)})
