"""dm_control ``humanoid``: stand, walk, run.

- Physics: MJX on the suite's ``humanoid.xml`` (Euler, 0.005 s; 5 physics steps per 0.025 s control step).
- Control: ``Box(-1, 1, (21,))``, torques on the abdomen, hips, knees, ankles, shoulders and elbows.
- Observation: ``joint_angles`` (21,) = qpos without the free root joint; ``head_height`` (); ``extremities``
  (12,) = left hand, left foot, right hand, right foot positions relative to the torso, in the torso frame;
  ``torso_vertical`` (3,) = the torso frame's z row (``zx, zy, zz``); ``com_velocity`` (3,) = the torso
  subtree's linear velocity (``torso_subtreelinvel``); ``velocity`` (27,) = qvel.
- Reward: ``small_control * standing * upright * move`` with ``standing = tolerance(head height, (1.4,
  inf), margin=0.35)``, ``upright = tolerance(torso zz, (0.9, inf), margin=1.9, linear,
  value_at_margin=0)``, ``small_control = (4 + mean(tolerance(ctrl, margin=1, quadratic,
  value_at_margin=0))) / 5``; stand: ``move = mean(tolerance(com x/y velocity, margin=2))``; walk and run:
  ``move = (5 * tolerance(|com x/y velocity|, (speed, inf), margin=speed, linear, value_at_margin=0) + 1)
  / 6``, speed 1 (walk) or 10 m/s (run). Success: none (the suite has no success criterion), always False.
- Episodes: 25 s = 1000 steps. Initial state: ``randomize_limited_and_rotational_joints`` (joints uniform
  in their ranges, the root's orientation from a normalised uniform [0, 1)^4 draw, root position kept),
  re-drawn while any contact penetrates (dm_control's ``ncon > 0``; every geom margin is 0, so a contact
  exists exactly when its distance is negative): an on-device loop of at most 100 draws (the suite's
  draws are accepted with probability ~0.74, so the limit is never reached in practice); zero velocity.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.arenas.mjx.dynamics import apply_params
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 25.0
_CONTROL_TIMESTEP = 0.025
_STAND_HEIGHT = 1.4
_WALK_SPEED = 1.0
_RUN_SPEED = 10.0
_MAX_DRAWS = 100
_EXTREMITIES = ("left_hand", "left_foot", "right_hand", "right_foot")


def dynamics() -> Dynamics:
    return common.domain_dynamics("humanoid", round(_CONTROL_TIMESTEP / common.load_model("humanoid").opt.timestep))


def _body(name: str) -> int:
    return common.names("humanoid").body(name)


def head_height(data) -> jax.Array:
    return data.xpos[_body("head"), 2]


def torso_upright(data) -> jax.Array:
    return common.xmat_entry(data, _body("torso"), "zz")


def center_of_mass_velocity(data) -> jax.Array:
    """The torso subtree's (the humanoid's centre of mass) linear velocity (3,), m/s."""
    return data.sensordata[common.names("humanoid").sensor("torso_subtreelinvel")]


def extremities(data) -> jax.Array:
    """Hands and feet relative to the torso, in the torso frame (12,)."""
    torso = _body("torso")
    limbs = np.array([_body(name) for name in _EXTREMITIES])
    return ((data.xpos[limbs] - data.xpos[torso]) @ data.xmat[torso]).ravel()


def observe(data, params):
    torso = _body("torso")
    obs = {"joint_angles": data.qpos[7:], "head_height": head_height(data), "extremities": extremities(data),
           "torso_vertical": data.xmat[torso, 2], "com_velocity": center_of_mass_velocity(data),
           "velocity": data.qvel}
    return {k: v.astype(jnp.float32) for k, v in obs.items()}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-humanoid")


def reward(data, move_speed: float) -> jax.Array:
    """The suite's ``Humanoid.get_reward`` on the state after a step."""
    standing = tolerance(head_height(data), (_STAND_HEIGHT, float("inf")), margin=_STAND_HEIGHT / 4)
    upright = tolerance(torso_upright(data), (0.9, float("inf")), sigmoid="linear", margin=1.9, value_at_margin=0)
    small_control = tolerance(data.ctrl, margin=1, value_at_margin=0, sigmoid="quadratic").mean()
    small_control = (4 + small_control) / 5
    horizontal_velocity = center_of_mass_velocity(data)[:2]
    if move_speed == 0:
        move = tolerance(horizontal_velocity, margin=2).mean()
    else:
        move = tolerance(jnp.linalg.norm(horizontal_velocity), (move_speed, float("inf")), margin=move_speed,
                         value_at_margin=0, sigmoid="linear")
        move = (5 * move + 1) / 6
    return small_control * standing * upright * move


@functools.cache
def _device_model() -> mjx.Model:
    model = common.load_model("humanoid")
    if np.any(model.geom_margin != 0):
        raise ValueError("humanoid's penetration test assumes zero geom margins")
    return common.device_model("humanoid")


def penetrating(m: mjx.Model, data: mjx.Data) -> jax.Array:
    """Whether any contact of ``data.qpos``'s configuration has negative distance (MuJoCo's ``ncon > 0``)."""
    d = mjx.collision(m, mjx.kinematics(m, data))
    return jnp.any(d._impl.contact.dist < 0)


def initialize(key, data, dynamics_params, params):
    """The suite's ``Humanoid.initialize_episode``: random joints, re-drawn while any contact penetrates."""
    model = common.load_model("humanoid")
    m = apply_params(_device_model(), dynamics_params)

    def draw(carry):
        tries, _, _ = carry
        qpos = common.randomize_limited_and_rotational_joints(jax.random.fold_in(key, tries), model, data.qpos)
        return tries + 1, qpos, penetrating(m, data.replace(qpos=qpos))

    def again(carry):
        tries, _, penetrates = carry
        return penetrates & (tries < _MAX_DRAWS)

    _, qpos, _ = jax.lax.while_loop(again, draw, (jnp.zeros((), jnp.int32), data.qpos, jnp.ones((), bool)))
    return data.replace(qpos=qpos)


def _humanoid(move_speed: float, name: str) -> Task:
    return common.suite_task(name, lambda data: reward(data, move_speed), initialize)


def stand() -> Task:
    return _humanoid(0.0, "stand")


def walk() -> Task:
    return _humanoid(_WALK_SPEED, "walk")


def run() -> Task:
    return _humanoid(_RUN_SPEED, "run")


DOMAIN = Domain(name="humanoid", dynamics=dynamics, sensor=sensor, tasks={"stand": stand, "walk": walk, "run": run},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("stand", "walk", "run")}, unread_sensors=("touch",))
