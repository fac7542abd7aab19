"""dm_control ``finger``: spin, turn_easy, turn_hard.

- Physics: MJX on the suite's ``finger.xml`` (Euler, 0.01 s, elliptic friction cones, no gravity; two
  physics steps per 0.02 s control step): a two-link finger (limited hinges) and a free spinner (hinge
  with friction loss) that touch through contacts.
- Per-task models: dm_control writes some constants into the model at every episode start; each
  task's model has them from the start. Spin: spinner damping 0.03 (the XML has 0.5) and the target
  and tip sites invisible. Turn: the target site's radius (0.07 m easy, 0.03 m hard). The target site
  sits in a mocap body, placed per episode in ``data.mocap_pos`` (dm_control moves the site in the
  model); sites do not collide and mocap bodies are static, so the dynamics are the suite's.
- Control: ``Box(-1, 1, (2,))``, torques on the proximal (gear 30) and distal (gear 15) joints.
- Observation (from the model's sensors): ``position`` (4,) = proximal and distal angles, then the
  spinner tip's x, z relative to the spinner; ``velocity`` (3,) = proximal, distal and spinner angular
  velocities; ``touch`` (2,) = ``log1p`` of the two fingertip touch sensors. Turn adds
  ``target_position`` (2,) = the target's x, z relative to the spinner and ``dist_to_target`` () = the
  tip's distance to the target's surface (negative inside).
- Reward: spin: 1 while the spinner turns at <= -15 rad/s, else 0; turn: 1 while the tip is inside the
  target (``dist_to_target <= 0``), else 0. Success: the same criteria.
- Episodes: 20 s = 1000 steps, no termination. Joints start uniform (finger hinges in their ranges,
  spinner in [-pi, pi)), at rest, redrawn until no geoms touch (dm_control's rejection loop, here at
  most 1000 draws, keeping the last); turn's target lies on the circle of radius 0.13 m around the
  spinner's hinge at an angle U[-pi, pi) from upright.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task

_TIME_LIMIT = 20.0
_CONTROL_TIMESTEP = 0.02
_PHYSICS_TIMESTEP = 0.01  # finger.xml's
_EASY_TARGET_SIZE = 0.07
_HARD_TARGET_SIZE = 0.03
_SPIN_VELOCITY = 15.0
_TARGET_XML = '<site name="target" type="sphere" size=".03" pos="0 0 .4" material="target"/>'
_HINGE_XML = '<joint name="hinge" frictionloss=".1" damping=".5"/>'
_TIP_XML = '<site name="tip" type="sphere"  size=".02" pos="0 0 .13" material="target"/>'
_INVISIBLE = ' rgba=".5 .5 .5 0"'  # what dm_control's spin leaves in site_rgba (alpha set to 0)


@dataclasses.dataclass(frozen=True)
class FingerEdit:
    """XML edit: the target site (radius ``target_size``) in a mocap body; for spin, the spinner's damping
    lowered to 0.03 and the target and tip sites made invisible, as ``Spin.initialize_episode`` does."""

    target_size: float
    spin: bool = False

    def __call__(self, xml: str) -> str:
        invisible = _INVISIBLE if self.spin else ""
        xml = common.replace_once(xml, _TARGET_XML,
                                  '<body name="target" mocap="true" pos="0 0 .4"><site name="target" type="sphere" '
                                  f'size="{self.target_size!r}" material="target"{invisible}/></body>')
        if self.spin:
            xml = common.replace_once(xml, _HINGE_XML, '<joint name="hinge" frictionloss=".1" damping=".03"/>')
            xml = common.replace_once(xml, _TIP_XML, _TIP_XML.replace("/>", invisible + "/>"))
        return xml


EDITS = {"spin": FingerEdit(0.03, spin=True), "turn_easy": FingerEdit(_EASY_TARGET_SIZE),
         "turn_hard": FingerEdit(_HARD_TARGET_SIZE)}
TASKS = tuple(EDITS)


def names(task: str) -> common.Names:
    return common.names("finger", edit=EDITS[task])


def dynamics(task: str = "spin") -> Dynamics:
    return common.domain_dynamics("finger", round(_CONTROL_TIMESTEP / _PHYSICS_TIMESTEP), edit=EDITS[task])


# ---------------------------------------------------------------- observations (sensor reads)
def _sensor(data, task: str, name: str) -> jax.Array:
    return data.sensordata[names(task).sensor(name)]


def tip_position(data, task: str) -> jax.Array:
    """The spinner tip's (x, z) relative to the spinner's hinge."""
    return (_sensor(data, task, "tip") - _sensor(data, task, "spinner"))[jnp.array([0, 2])]


def target_position(data, task: str) -> jax.Array:
    """The target's (x, z) relative to the spinner's hinge."""
    return (_sensor(data, task, "target") - _sensor(data, task, "spinner"))[jnp.array([0, 2])]


def hinge_velocity(data, task: str) -> jax.Array:
    return _sensor(data, task, "hinge_velocity")[0]


def target_size(task: str) -> float:
    n = names(task)
    return float(n.model.site_size[n.site("target"), 0])


def dist_to_target(data, task: str) -> jax.Array:
    """Signed distance (m) from the tip to the target's surface, negative inside."""
    return jnp.linalg.norm(target_position(data, task) - tip_position(data, task)) - target_size(task)


def _observe(task: str, data) -> dict[str, jax.Array]:
    s = functools.partial(_sensor, data, task)
    obs = {"position": jnp.concatenate([s("proximal"), s("distal"), tip_position(data, task)]),
           "velocity": jnp.concatenate([s("proximal_velocity"), s("distal_velocity"), s("hinge_velocity")]),
           "touch": jnp.log1p(jnp.concatenate([s("touchtop"), s("touchbottom")]))}
    if task != "spin":
        obs["target_position"] = target_position(data, task)
        obs["dist_to_target"] = dist_to_target(data, task)
    return {k: v.astype(jnp.float32) for k, v in obs.items()}


def sensor(task: str = "spin") -> Sensor:
    return Sensor(observe=lambda data, params: _observe(task, data), name=f"dmc-finger-{task}")


# ---------------------------------------------------------------- tasks
@functools.cache
def hinge_anchor_and_radius(task: str) -> tuple[np.ndarray, float]:
    """The spinner hinge's (x, z) anchor (m) and ``geom_size['cap1'].sum()`` (the target circle's radius)."""
    n = names(task)
    data = mujoco.MjData(n.model)
    mujoco.mj_kinematics(n.model, data)
    anchor = data.xanchor[n.joint("hinge")][[0, 2]].copy()
    return anchor, float(n.model.geom_size[n.geom("cap1")].sum())


def _random_joints(task: str):
    model = names(task).model

    def sample(key, data):
        return data.replace(qpos=common.randomize_limited_and_rotational_joints(key, model, data.qpos))
    return sample


def _finger(task: str) -> Task:
    turn = task != "spin"
    device_model = common.device_model("finger", edit=EDITS[task])

    def success(data):
        if turn:
            return dist_to_target(data, task) <= 0
        return hinge_velocity(data, task) <= -_SPIN_VELOCITY

    def initialize(key, data, dynamics_params, params):
        k_target, k_joints = jax.random.split(key)
        if turn:
            anchor, radius = hinge_anchor_and_radius(task)
            angle = jax.random.uniform(k_target, (), minval=-jnp.pi, maxval=jnp.pi)
            xz = jnp.asarray(anchor) + radius * jnp.stack([jnp.sin(angle), jnp.cos(angle)])
            data = data.replace(mocap_pos=data.mocap_pos.at[0, jnp.array([0, 2])].set(xz))
        return common.sample_collision_free(k_joints, data, _random_joints(task), device_model)

    def reset(key, data, outcome, params):
        return outcome.replace(success=success(data)), ()

    def update(state, outcome, transition, params):
        hit = success(transition.physics)
        return outcome.replace(reward=outcome.reward + hit.astype(jnp.float32), success=hit), state

    return Task(update=update, reset=reset, initialize=initialize, name=task, has_success=True)


def spin() -> Task:
    return _finger("spin")


def turn_easy() -> Task:
    return _finger("turn_easy")


def turn_hard() -> Task:
    return _finger("turn_hard")


DOMAIN = Domain(name="finger", dynamics=dynamics, sensor=sensor,
                tasks={"spin": spin, "turn_easy": turn_easy, "turn_hard": turn_hard},
                task_dynamics={t: functools.partial(dynamics, t) for t in TASKS},
                sensors={t: functools.partial(sensor, t) for t in TASKS},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in TASKS})
