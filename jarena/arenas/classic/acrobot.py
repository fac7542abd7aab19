"""Acrobot swing-up, matching Gymnasium's ``Acrobot-v1`` (Sutton, 1996; Sutton & Barto's "book" dynamics).

- Physics: ``AcrobotState`` of float32 scalars ``theta1`` (rad, 0 = hanging down), ``theta2`` (rad,
  relative to link 1), ``theta1_dot`` and ``theta2_dot`` (rad/s). One step is a single fourth-order
  Runge-Kutta step over ``[0, dt = 0.2]`` s of the book's equations of motion with the torque held
  constant; then both angles are wrapped to [-pi, pi] and the velocities clipped to ``[-4 pi, 4 pi]``
  and ``[-9 pi, 9 pi]``.
- Control: ``Discrete(3)``: torques -1, 0, +1 on the joint between the links; the no-op is 1 (no torque).
- Observation: ``{"state": float32 (6,)}`` = (cos theta1, sin theta1, cos theta2, sin theta2,
  theta1_dot, theta2_dot), bounds (1, 1, 1, 1, 4 pi, 9 pi).
- Task ``swingup``: reward -1 every step, 0 on the step that reaches the goal; terminated when the tip
  is above the bar, ``-cos(theta1) - cos(theta1 + theta2) > 1``; success when the goal is reached;
  500-step time limit.
- Initial state: each variable uniform in [-0.1, 0.1].
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.spec import Box, Dict, Discrete
from jarena.core.task import Task
from jarena.core.tree import as_float32
from jarena.render.classic import draw_acrobot


@struct.dataclass
class AcrobotState:
    theta1: jax.Array
    theta2: jax.Array
    theta1_dot: jax.Array
    theta2_dot: jax.Array


@struct.dataclass
class AcrobotParams:
    dt: jax.Array = 0.2
    link_length_1: jax.Array = 1.0
    link_mass_1: jax.Array = 1.0
    link_mass_2: jax.Array = 1.0
    link_com_pos_1: jax.Array = 0.5
    link_com_pos_2: jax.Array = 0.5
    link_moi: jax.Array = 1.0  # moment of inertia of both links
    max_vel_1: jax.Array = 4 * math.pi
    max_vel_2: jax.Array = 9 * math.pi
    gravity: jax.Array = 9.8
    torques: jax.Array = struct.field(default_factory=lambda: np.array([-1.0, 0.0, 1.0]))  # per discrete action
    init_range: jax.Array = 0.1


@struct.dataclass
class SwingupParams:
    height: jax.Array = 1.0  # goal: the tip's height above the pivot, in units of link length, exceeds this


def init(key, params: AcrobotParams) -> AcrobotState:
    s = jax.random.uniform(key, (4,), jnp.float32, -params.init_range, params.init_range)
    return AcrobotState(theta1=s[0], theta2=s[1], theta1_dot=s[2], theta2_dot=s[3])


def _dsdt(s, torque, p: AcrobotParams):
    """Gymnasium's ``_dsdt`` with ``book_or_nips = "book"``; ``s`` = (theta1, theta2, dtheta1, dtheta2)."""
    m1, m2, l1 = p.link_mass_1, p.link_mass_2, p.link_length_1
    lc1, lc2, i1, i2, g = p.link_com_pos_1, p.link_com_pos_2, p.link_moi, p.link_moi, p.gravity
    theta1, theta2, dtheta1, dtheta2 = s[0], s[1], s[2], s[3]
    d1 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * jnp.cos(theta2)) + i1 + i2
    d2 = m2 * (lc2**2 + l1 * lc2 * jnp.cos(theta2)) + i2
    phi2 = m2 * lc2 * g * jnp.cos(theta1 + theta2 - jnp.pi / 2.0)
    phi1 = (-m2 * l1 * lc2 * dtheta2**2 * jnp.sin(theta2)
            - 2 * m2 * l1 * lc2 * dtheta2 * dtheta1 * jnp.sin(theta2)
            + (m1 * lc1 + m2 * l1) * g * jnp.cos(theta1 - jnp.pi / 2) + phi2)
    ddtheta2 = ((torque + d2 / d1 * phi1 - m2 * l1 * lc2 * dtheta1**2 * jnp.sin(theta2) - phi2)
                / (m2 * lc2**2 + i2 - d2**2 / d1))
    ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
    return jnp.stack([dtheta1, dtheta2, ddtheta1, ddtheta2])


def _wrap(x, low, high):
    """Gymnasium's ``wrap``: shifts ``x`` by whole periods ``high - low`` until ``low <= x <= high``."""
    period = high - low
    return jnp.where(x > high, x - period * jnp.ceil((x - high) / period),
                     jnp.where(x < low, x + period * jnp.ceil((low - x) / period), x))


def step(state: AcrobotState, action, params: AcrobotParams) -> AcrobotState:
    torque = params.torques[action]
    s = jnp.stack([state.theta1, state.theta2, state.theta1_dot, state.theta2_dot])
    dt = params.dt
    k1 = _dsdt(s, torque, params)
    k2 = _dsdt(s + dt / 2 * k1, torque, params)
    k3 = _dsdt(s + dt / 2 * k2, torque, params)
    k4 = _dsdt(s + dt * k3, torque, params)
    ns = s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return AcrobotState(theta1=_wrap(ns[0], -jnp.pi, jnp.pi), theta2=_wrap(ns[1], -jnp.pi, jnp.pi),
                        theta1_dot=jnp.clip(ns[2], -params.max_vel_1, params.max_vel_1),
                        theta2_dot=jnp.clip(ns[3], -params.max_vel_2, params.max_vel_2))


def observe(state: AcrobotState, params) -> dict[str, jax.Array]:
    return {"state": jnp.stack([jnp.cos(state.theta1), jnp.sin(state.theta1), jnp.cos(state.theta2),
                                jnp.sin(state.theta2), state.theta1_dot, state.theta2_dot]).astype(jnp.float32)}


_HIGH = np.array([1.0, 1.0, 1.0, 1.0, 4 * math.pi, 9 * math.pi], np.float32)
OBSERVATION_SPEC = Dict(state=Box(-_HIGH, _HIGH, dtype=jnp.float32))


def swingup() -> Task:
    """Swing the tip above the bar (Gymnasium's reward and termination)."""

    def reached(physics, params):
        return -jnp.cos(physics.theta1) - jnp.cos(physics.theta2 + physics.theta1) > params.height

    def reset(key, physics, outcome, params):
        return outcome.replace(success=reached(physics, params)), ()

    def update(state, outcome, transition, params):
        done = reached(transition.physics, params)
        return outcome.replace(reward=outcome.reward + jnp.where(done, 0.0, -1.0),
                               terminated=outcome.terminated | done, success=done), state

    return Task(update=update, reset=reset, default_params=lambda: as_float32(SwingupParams()), name="swingup",
                has_success=True)


def dynamics() -> Dynamics:
    return Dynamics(init=init, step=step, control_spec=Discrete(3), default_params=lambda: as_float32(AcrobotParams()),
                    no_op=lambda: jnp.asarray(1, jnp.int32), timestep=0.2, render=draw_acrobot,
                    name="acrobot")


def sensor() -> Sensor:
    return Sensor(observe=observe, spec=OBSERVATION_SPEC, name="acrobot_state")


DOMAIN = Domain(name="acrobot", dynamics=dynamics, sensor=sensor, tasks={"swingup": swingup}, time_limit=500,
                tags={"swingup": ("benchmark",)})
