"""dm_control ``reacher``: easy, hard.

- Physics: MJX on the suite's ``reacher.xml`` (Euler, 0.02 s; one physics step per control step;
  contacts off): a two-link planar arm (free shoulder, wrist limited to +-160 deg).
- Target: dm_control moves the target geom in the *model* each episode. Here the target geom sits in
  a mocap body, placed per episode in ``data.mocap_pos``, and its radius is the task's (0.05 m easy,
  0.015 m hard) in each task's model. Mocap bodies are static and contacts are off, so the arm's
  dynamics are the suite's (the tests step both models).
- Control: ``Box(-1, 1, (2,))``, torques on shoulder and wrist (gear 0.05).
- Observation: ``position`` (2,) = qpos; ``to_target`` (2,) = the target's minus the finger's x, y;
  ``velocity`` (2,) = qvel.
- Reward: 1 while the finger touches the target (distance <= target radius + finger radius 0.01 m),
  else 0 (``tolerance`` without margin). Success: the same criterion.
- Episodes: 20 s = 1000 steps, no termination; joints start uniform (shoulder in [-pi, pi), wrist in its
  range), at rest; the target at angle U[0, 2 pi), radius U[0.05, 0.2) m from the shoulder.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 20.0
_CONTROL_TIMESTEP = 0.02  # the model's timestep: control.Environment's default of one physics step
_BIG_TARGET = 0.05
_SMALL_TARGET = 0.015
_TARGET_XML = '<geom name="target" pos="0 0 .01" material="target" type="sphere" size=".05"/>'


@dataclasses.dataclass(frozen=True)
class TargetEdit:
    """XML edit: the target geom (of radius ``size``) in a mocap body at the geom's place."""

    size: float

    def __call__(self, xml: str) -> str:
        return common.replace_once(xml, _TARGET_XML,
                                   '<body name="target" mocap="true" pos="0 0 .01"><geom name="target" '
                                   f'material="target" type="sphere" size="{self.size!r}"/></body>')


EDITS = {"easy": TargetEdit(_BIG_TARGET), "hard": TargetEdit(_SMALL_TARGET)}


def names(task: str = "easy") -> common.Names:
    return common.names("reacher", edit=EDITS[task])


def dynamics(task: str = "easy") -> Dynamics:
    return common.domain_dynamics("reacher", 1, edit=EDITS[task])


def finger_to_target(data) -> jax.Array:
    """The target's minus the finger's x, y position (m)."""
    n = names()  # both tasks' models number their geoms alike
    return data.geom_xpos[n.geom("target"), :2] - data.geom_xpos[n.geom("finger"), :2]


def observe(data, params):
    return {"position": data.qpos.astype(jnp.float32), "to_target": finger_to_target(data).astype(jnp.float32),
            "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-reacher")


def radii(task: str) -> float:
    """``geom_size[['target', 'finger'], 0].sum()`` of the task's model."""
    n = names(task)
    return float(n.model.geom_size[n.geom("target"), 0] + n.model.geom_size[n.geom("finger"), 0])


def _reacher(task: str) -> Task:
    limit = radii(task)

    def touching(data):
        return tolerance(jnp.linalg.norm(finger_to_target(data)), (0.0, limit))

    def initialize(key, data, dynamics_params, params):
        k_joints, k_angle, k_radius = jax.random.split(key, 3)
        qpos = common.randomize_limited_and_rotational_joints(k_joints, names(task).model, data.qpos)
        angle = jax.random.uniform(k_angle, (), minval=0.0, maxval=2 * jnp.pi)
        radius = jax.random.uniform(k_radius, (), minval=0.05, maxval=0.20)
        target = data.mocap_pos[0].at[:2].set(jnp.stack([radius * jnp.sin(angle), radius * jnp.cos(angle)]))
        return data.replace(qpos=qpos, mocap_pos=data.mocap_pos.at[0].set(target))

    def reset(key, data, outcome, params):
        return outcome.replace(success=touching(data) > 0), ()

    def update(state, outcome, transition, params):
        reward = touching(transition.physics)
        return outcome.replace(reward=outcome.reward + reward, success=reward > 0), state

    return Task(update=update, reset=reset, initialize=initialize, name=task, has_success=True)


def easy() -> Task:
    return _reacher("easy")


def hard() -> Task:
    return _reacher("hard")


DOMAIN = Domain(name="reacher", dynamics=dynamics, sensor=sensor, tasks={"easy": easy, "hard": hard},
                task_dynamics={"hard": lambda: dynamics("hard")},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("easy", "hard")})
