"""dm_control ``fish``: upright, swim.

- Physics: MJX on the suite's ``fish.xml`` (Euler, 0.004 s; 10 physics steps per 0.04 s control step;
  fluid drag from ``density``; gravity and all constraints disabled by the model's flags, so MuJoCo never
  runs collision detection). Two edits that leave the dynamics unchanged (tests step MuJoCo on both
  models to equal states): every geom gets ``contype = conaffinity = 0`` (MJX builds its collision table
  from these bits, and cannot collide the tail's ellipsoid with the torso's massive box; it would also
  compute every other pair's contacts in each step, which MuJoCo skips), and the target is a mocap body,
  so its per-episode position is ``data.mocap_pos[0]`` in the physics state.
- Control: ``Box(-1, 1, (5,))``, position servos on the tail, tail twist, fin flapping and the two fins'
  pitch.
- Observation: ``joint_angles`` (7,) = tail1, tail_twist, tail2, finright_roll, finright_pitch,
  finleft_roll, finleft_pitch; ``upright`` () = torso zz; swim adds ``target`` (3,) = target minus mouth
  position in the mouth's frame; ``velocity`` (13,) = qvel.
- Reward: upright: ``tolerance(torso zz, (1, 1), margin=1)``; swim: ``(7 * in_target + (1 + torso zz) / 2)
  / 8`` with ``in_target = tolerance(|mouth to target|, (0, r), margin=2 r)``, r = mouth + target radius.
  Success: none (the suite has no success criterion), always False.
- Episodes: 40 s = 1000 steps. Initial state: the root orientation uniform (a normalised Gaussian
  quaternion), each listed joint uniform in [-0.2, 0.2], zero velocity; swim places the target uniformly
  in [-0.4, 0.4]^2 x [0.1, 0.3]. Upright leaves the (unobserved) target where the model has it; the suite
  also makes it transparent, which a shared model cannot, so renders of upright show it.
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

_TIME_LIMIT = 40.0
_CONTROL_TIMESTEP = 0.04
_JOINTS = ("tail1", "tail_twist", "tail2", "finright_roll", "finright_pitch", "finleft_roll", "finleft_pitch")


def mjx_xml(xml: str) -> str:
    """The suite's fish XML made MJX-ready: no geom in the collision table, the target a mocap body."""
    return common.without_collisions_target_as_mocap(xml)


def model():
    return common.load_model("fish", edit=mjx_xml)


def dynamics() -> Dynamics:
    return common.domain_dynamics("fish", round(_CONTROL_TIMESTEP / model().opt.timestep), edit=mjx_xml)


def _names():
    return common.names("fish", edit=mjx_xml)


def _joint_qpos() -> np.ndarray:
    return np.array([_names().qpos(j) for j in _JOINTS])


def upright(data) -> jax.Array:
    return common.xmat_entry(data, _names().body("torso"), "zz")


def mouth_to_target(data) -> jax.Array:
    """Target minus mouth position in the mouth's frame (3,)."""
    names = _names()
    mouth = names.geom("mouth")
    return (data.geom_xpos[names.geom("target")] - data.geom_xpos[mouth]) @ data.geom_xmat[mouth]


def _observe(with_target: bool):
    def observe(data, params):
        obs = {"joint_angles": data.qpos[_joint_qpos()], "upright": upright(data)}
        if with_target:
            obs["target"] = mouth_to_target(data)
        obs["velocity"] = data.qvel
        return {k: v.astype(jnp.float32) for k, v in obs.items()}

    return observe


def sensor() -> Sensor:
    return Sensor(observe=_observe(False), name="dmc-fish")


def swim_sensor() -> Sensor:
    return Sensor(observe=_observe(True), name="dmc-fish-swim")


def _radii() -> float:
    names = _names()
    return float(model().geom_size[names.geom("mouth"), 0] + model().geom_size[names.geom("target"), 0])


def reward(data, swim: bool) -> jax.Array:
    """The suite's ``Upright.get_reward`` or ``Swim.get_reward`` on the state after a step."""
    if not swim:
        return tolerance(upright(data), (1.0, 1.0), margin=1)
    radii = _radii()
    in_target = tolerance(jnp.linalg.norm(mouth_to_target(data)), (0.0, radii), margin=2 * radii)
    is_upright = 0.5 * (upright(data) + 1)
    return (7 * in_target + is_upright) / 8


def _initialize(swim: bool):
    def initialize(key, data, dynamics_params, params):
        k_quat, k_joints, k_target = jax.random.split(key, 3)
        root = _names().qpos("root")
        quat = jax.random.normal(k_quat, (4,))
        qpos = data.qpos.at[root + 3:root + 7].set(quat / jnp.linalg.norm(quat))
        qpos = qpos.at[_joint_qpos()].set(jax.random.uniform(k_joints, (len(_JOINTS),), minval=-0.2, maxval=0.2))
        data = data.replace(qpos=qpos)
        if swim:
            target = jax.random.uniform(k_target, (3,), minval=jnp.array([-0.4, -0.4, 0.1]),
                                        maxval=jnp.array([0.4, 0.4, 0.3]))
            data = data.replace(mocap_pos=data.mocap_pos.at[0].set(target.astype(data.mocap_pos.dtype)))
        return data

    return initialize


def _fish(swim: bool, name: str) -> Task:
    return common.suite_task(name, lambda data: reward(data, swim), _initialize(swim))


def upright_task() -> Task:
    return _fish(False, "upright")


def swim() -> Task:
    return _fish(True, "swim")


DOMAIN = Domain(name="fish", dynamics=dynamics, sensor=sensor, tasks={"upright": upright_task, "swim": swim},
                sensors={"swim": swim_sensor}, time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP),
                auto_reset="lazy", tags={t: ("benchmark",) for t in ("upright", "swim")})
