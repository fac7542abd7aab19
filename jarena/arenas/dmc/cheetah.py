"""dm_control ``cheetah``: run.

- Physics: MJX on the suite's ``cheetah.xml`` (Euler, 0.01 s; one physics step per control step).
- Control: ``Box(-1, 1, (6,))``, torques on the back and front thigh, shin and foot.
- Observation: ``position`` (8,) = qpos without the horizontal root position; ``velocity`` (9,) = qvel.
- Reward: ``tolerance(speed, (10, inf), margin=10, linear, value_at_margin=0)``, i.e. the torso subtree's
  forward velocity (``torso_subtreelinvel`` x) over 10 m/s, linear from 0 at standstill. Success: none
  (the suite has no success criterion), always False.
- Episodes: 10 s = 1000 steps. Initial state as the suite: limited joints uniform in their range, then
  200 physics steps with zero control to settle (the first from the stale kinematics of ``qpos0``, as
  dm_control steps right after its reset), time reset to 0.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from jarena.arenas.dmc import common
from jarena.arenas.domain import Domain
from jarena.arenas.mjx.dynamics import apply_params, integrate, observe_state
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.tasks.tolerance import tolerance

_TIME_LIMIT = 10.0
_CONTROL_TIMESTEP = 0.01  # the suite's default: the physics timestep
_RUN_SPEED = 10.0
_SETTLE_STEPS = 200


def dynamics() -> Dynamics:
    return common.domain_dynamics("cheetah", 1)


def observe(data, params):
    return {"position": data.qpos[1:].astype(jnp.float32), "velocity": data.qvel.astype(jnp.float32)}


def sensor() -> Sensor:
    return Sensor(observe=observe, name="dmc-cheetah")


def speed(data) -> jax.Array:
    """The torso subtree's forward velocity (m/s)."""
    return data.sensordata[common.names("cheetah").sensor("torso_subtreelinvel")][0]


def reward(data) -> jax.Array:
    return tolerance(speed(data), (_RUN_SPEED, float("inf")), margin=_RUN_SPEED, value_at_margin=0,
                     sigmoid="linear")


@functools.cache
def _device_model() -> mjx.Model:
    return common.device_model("cheetah")


def draw_limited_joints(key: jax.Array) -> tuple[np.ndarray, jax.Array]:
    """``(qpos addresses, values)``: the limited joints uniform in their ranges (the suite's draw)."""
    model = common.load_model("cheetah")
    limited = np.flatnonzero(model.jnt_limited == 1)
    low, high = model.jnt_range[limited].T
    return model.jnt_qposadr[limited], jax.random.uniform(key, (len(limited),), minval=low, maxval=high)


def initialize(key, data, dynamics_params, params):
    """The suite's ``Cheetah.initialize_episode`` on MJX (the caller's ``after_reset`` forwards the result).

    dm_control resets to ``qpos0`` (forwarded), writes the random joints and calls ``physics.step(200)``:
    its first step integrates with the kinematics of ``qpos0``. Each iteration here is that order
    (``mj_step1`` then ``mj_step2``), with the random joints written after the first ``mj_step1``.

    The settling runs on the suite's model (its solver and contacts) whatever simulation options the
    arena was built with, and only the state variables (qpos, qvel, act, the solver's warm start) are
    handed back into ``data``: the arena's own model may size its contact arrays differently (MJX
    contact culling).
    """
    m = apply_params(_device_model(), dynamics_params)
    adr, values = draw_limited_joints(key)
    randomized = data.qpos.at[adr].set(values)
    model = common.load_model("cheetah")
    start = mjx.make_data(model).replace(qpos=jnp.asarray(model.qpos0, data.qpos.dtype),
                                         qacc_warmstart=data.qacc_warmstart, act=data.act)

    def step(i, d):
        d = observe_state(m, d)
        # the line search as a while loop, as the arena's steps run it: the same states, sooner
        return integrate(m, d.replace(qpos=jnp.where(i == 0, randomized, d.qpos)), differentiable=False)

    settled = jax.lax.fori_loop(0, _SETTLE_STEPS, step, start)
    return data.replace(qpos=settled.qpos, qvel=settled.qvel, act=settled.act, ctrl=jnp.zeros_like(data.ctrl),
                        qacc_warmstart=settled.qacc_warmstart, time=jnp.zeros_like(data.time))


def run() -> Task:
    return common.suite_task("run", reward, initialize)


DOMAIN = Domain(name="cheetah", dynamics=dynamics, sensor=sensor, tasks={"run": run},
                time_limit=common.steps(_TIME_LIMIT, _CONTROL_TIMESTEP), auto_reset="lazy",
                tags={"run": ("benchmark",)})
