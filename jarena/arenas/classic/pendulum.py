"""Pendulum swing-up, matching Gymnasium's ``Pendulum-v1``.

- Physics: ``PendulumState`` of float32 scalars ``theta`` (rad, 0 = upright, *not* wrapped, as in
  Gymnasium) and ``theta_dot`` (rad/s); semi-implicit Euler with ``dt = 0.05`` s:
  ``theta_dot += (3 g / (2 l) sin(theta) + 3 / (m l^2) u) dt``, clipped to ``[-8, 8]``, then
  ``theta += theta_dot dt``; ``g = 10``, ``m = l = 1``.
- Control: ``Box(-2, 2, (1,))``, a torque; values outside are clipped to ``[-max_torque, max_torque]``.
- Observation: ``{"state": float32 (3,)}`` = (cos theta, sin theta, theta_dot), bounds (1, 1, 8).
- Task ``swingup``: reward ``-(angle_normalize(theta)^2 + 0.1 theta_dot^2 + 0.001 u^2)`` of the state
  *before* the step and the clipped torque ``u``; never terminates; 200-step time limit. Success (not in
  Gymnasium) holds at a step when ``|angle_normalize(theta)| < 0.1`` rad and ``|theta_dot| < 1`` rad/s;
  metric ``upright`` is ``cos(theta)``.
- Initial state: ``theta`` uniform in [-pi, pi], ``theta_dot`` uniform in [-1, 1].
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.domain import Domain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.spec import Box, Dict
from jarena.core.task import Task
from jarena.core.tree import as_float32
from jarena.render.classic import draw_pendulum


@struct.dataclass
class PendulumState:
    theta: jax.Array
    theta_dot: jax.Array


@struct.dataclass
class PendulumParams:
    max_torque: jax.Array = 2.0
    max_speed: jax.Array = 8.0
    dt: jax.Array = 0.05
    g: jax.Array = 10.0
    m: jax.Array = 1.0
    l: jax.Array = 1.0  # noqa: E741  (Gymnasium's name)
    init_theta: jax.Array = math.pi  # theta ~ U[-init_theta, init_theta] (Gymnasium's x_init)
    init_theta_dot: jax.Array = 1.0  # theta_dot ~ U[-init_theta_dot, init_theta_dot] (Gymnasium's y_init)


@struct.dataclass
class SwingupParams:
    success_angle: jax.Array = 0.1
    success_speed: jax.Array = 1.0


def angle_normalize(x):
    """Wraps an angle to [-pi, pi) (Gymnasium's ``angle_normalize``)."""
    return ((x + jnp.pi) % (2 * jnp.pi)) - jnp.pi


def init(key, params: PendulumParams) -> PendulumState:
    high = jnp.stack([params.init_theta, params.init_theta_dot])
    s = jax.random.uniform(key, (2,), jnp.float32, -high, high)
    return PendulumState(theta=s[0], theta_dot=s[1])


def step(state: PendulumState, control, params: PendulumParams) -> PendulumState:
    u = jnp.clip(control[0], -params.max_torque, params.max_torque)
    theta_dot = state.theta_dot + (3 * params.g / (2 * params.l) * jnp.sin(state.theta)
                                   + 3.0 / (params.m * params.l**2) * u) * params.dt
    theta_dot = jnp.clip(theta_dot, -params.max_speed, params.max_speed)
    return PendulumState(theta=state.theta + theta_dot * params.dt, theta_dot=theta_dot)


def observe(state: PendulumState, params) -> dict[str, jax.Array]:
    return {"state": jnp.stack([jnp.cos(state.theta), jnp.sin(state.theta), state.theta_dot]).astype(jnp.float32)}


OBSERVATION_SPEC = Dict(state=Box(-np.array([1.0, 1.0, 8.0]), np.array([1.0, 1.0, 8.0]), dtype=jnp.float32))


def swingup() -> Task:
    """Swing the pendulum up and hold it upright (Gymnasium's reward; success near upright and slow)."""

    def succeeded(physics, params):
        return ((jnp.abs(angle_normalize(physics.theta)) < params.success_angle)
                & (jnp.abs(physics.theta_dot) < params.success_speed))

    def reset(key, physics, outcome, params):
        return outcome.replace(success=succeeded(physics, params),
                               metrics=dict(outcome.metrics, upright=jnp.cos(physics.theta))), ()

    def update(state, outcome, transition, params):
        prev = transition.previous
        max_torque = transition.dynamics_params.max_torque  # the same clip as the dynamics
        u = jnp.clip(transition.control[0], -max_torque, max_torque)
        costs = angle_normalize(prev.theta) ** 2 + 0.1 * prev.theta_dot**2 + 0.001 * u**2
        physics = transition.physics
        return outcome.replace(reward=outcome.reward - costs, success=succeeded(physics, params),
                               metrics=dict(outcome.metrics, upright=jnp.cos(physics.theta))), state

    return Task(update=update, reset=reset, default_params=lambda: as_float32(SwingupParams()), name="swingup",
                has_success=True)


def dynamics() -> Dynamics:
    return Dynamics(init=init, step=step, control_spec=Box(-2.0, 2.0, (1,), jnp.float32),
                    default_params=lambda: as_float32(PendulumParams()), timestep=0.05, render=draw_pendulum,
                    name="pendulum")


def sensor() -> Sensor:
    return Sensor(observe=observe, spec=OBSERVATION_SPEC, name="pendulum_state")


DOMAIN = Domain(name="pendulum", dynamics=dynamics, sensor=sensor, tasks={"swingup": swingup}, time_limit=200,
                tags={"swingup": ("benchmark",)})
