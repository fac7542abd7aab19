"""dm_control ``walker``: stand, walk, run.

- Physics: MJX on the suite's ``walker.xml`` (Euler, 0.0025 s; 10 physics steps per 0.025 s control step).
- Control: ``Box(-1, 1, (6,))``, torques on the right and left hip, knee and ankle.
- Observation: ``orientations`` (14,) = ``xx`` and ``xz`` entries of every body's frame (torso, right
  thigh, leg, foot, left thigh, leg, foot; body by body); ``height`` () = torso height; ``velocity`` (9,)
  = qvel.
- Reward: ``stand = (3 * standing + upright) / 4`` with ``standing = tolerance(torso height, (1.2, inf),
  margin=0.6)`` and ``upright = (1 + torso zz) / 2``; stand returns it, walk and run multiply it by
  ``(5 * move + 1) / 6`` with ``move = tolerance(torso subtree x velocity, (speed, inf), margin=speed / 2,
  linear, value_at_margin=0.5)``, speed 1 (walk) or 8 m/s (run). Success: none (the suite has no success
  criterion), always False.
- Episodes: 25 s = 1000 steps. Initial state: ``randomize_limited_and_rotational_joints`` (joints uniform
  in their ranges, the root's pitch uniform in [-pi, pi], root position kept), zero velocity; the suite
  does not reject configurations that penetrate the floor (about 2% of its starts).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 25.0
_CONTROL_TIMESTEP = 0.025
_STAND_HEIGHT = 1.2
_WALK_SPEED = 1.0
_RUN_SPEED = 8.0


def dynamics() -> Dynamics:
    return common.domain_dynamics("walker", round(_CONTROL_TIMESTEP / common.load_model("walker").opt.timestep))


def _torso() -> int:
    return common.names("walker").body("torso")


def torso_height(data) -> jax.Array:
    return data.xpos[_torso(), 2]


def torso_upright(data) -> jax.Array:
    return common.xmat_entry(data, _torso(), "zz")


def horizontal_velocity(data) -> jax.Array:
    """The torso subtree's (the walker's centre of mass) forward velocity (m/s)."""
    return data.sensordata[common.names("walker").sensor("torso_subtreelinvel")][0]


def observe(data, params):
    orientations = data.xmat[1:, 0][:, jnp.array([0, 2])].ravel()
    return {"orientations": orientations.astype(jnp.float32), "height": torso_height(data).astype(jnp.float32),
            "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-walker")


def reward(data, move_speed: float) -> jax.Array:
    """The suite's ``PlanarWalker.get_reward`` on the state after a step."""
    standing = tolerance(torso_height(data), (_STAND_HEIGHT, float("inf")), margin=_STAND_HEIGHT / 2)
    upright = (1 + torso_upright(data)) / 2
    stand_reward = (3 * standing + upright) / 4
    if move_speed == 0:
        return stand_reward
    move_reward = tolerance(horizontal_velocity(data), (move_speed, float("inf")), margin=move_speed / 2,
                            value_at_margin=0.5, sigmoid="linear")
    return stand_reward * (5 * move_reward + 1) / 6


def initialize(key, data, dynamics_params, params):
    """The suite's ``PlanarWalker.initialize_episode``: random joints, velocities as reset (zero)."""
    return data.replace(qpos=common.randomize_limited_and_rotational_joints(key, common.load_model("walker"),
                                                                            data.qpos))


def _walker(move_speed: float, name: str) -> Task:
    return common.suite_task(name, lambda data: reward(data, move_speed), initialize)


def stand() -> Task:
    return _walker(0.0, "stand")


def walk() -> Task:
    return _walker(_WALK_SPEED, "walk")


def run() -> Task:
    return _walker(_RUN_SPEED, "run")


DOMAIN = Domain(name="walker", dynamics=dynamics, sensor=sensor, tasks={"stand": stand, "walk": walk, "run": run},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={t: ("benchmark",) for t in ("stand", "walk", "run")})
