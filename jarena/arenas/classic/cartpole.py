"""Cart-pole, matching Gymnasium's ``CartPole-v1`` (Barto, Sutton & Anderson, 1983).

- Physics: ``CartPoleState`` of float32 scalars ``x`` (m), ``x_dot`` (m/s), ``theta`` (rad, 0 = upright),
  ``theta_dot`` (rad/s); explicit Euler with ``tau = 0.02`` s.
- Control: ``Discrete(2)``: 0 pushes the cart left, 1 right, with ``force_mag`` newtons.
- Observation: ``{"state": float32 (4,)}`` = (x, x_dot, theta, theta_dot).
- Task ``balance``: reward 1 every step (including the terminating one); terminated when
  ``|x| > 2.4`` or ``|theta| > 12 degrees``; success while not terminated; 500-step time limit.
- Initial state: each variable uniform in [-0.05, 0.05].
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
from jarena.render.classic import draw_cartpole


@struct.dataclass
class CartPoleState:
    x: jax.Array
    x_dot: jax.Array
    theta: jax.Array
    theta_dot: jax.Array


@struct.dataclass
class CartPoleParams:
    gravity: jax.Array = 9.8
    masscart: jax.Array = 1.0
    masspole: jax.Array = 0.1
    length: jax.Array = 0.5  # half the pole's length
    force_mag: jax.Array = 10.0
    tau: jax.Array = 0.02
    init_range: jax.Array = 0.05


@struct.dataclass
class BalanceParams:
    x_threshold: jax.Array = 2.4
    theta_threshold: jax.Array = 12 * 2 * math.pi / 360


def init(key, params: CartPoleParams) -> CartPoleState:
    s = jax.random.uniform(key, (4,), jnp.float32, -params.init_range, params.init_range)
    return CartPoleState(x=s[0], x_dot=s[1], theta=s[2], theta_dot=s[3])


def step(state: CartPoleState, action, params: CartPoleParams) -> CartPoleState:
    force = jnp.where(action == 1, params.force_mag, -params.force_mag)
    total_mass = params.masspole + params.masscart
    polemass_length = params.masspole * params.length
    costheta, sintheta = jnp.cos(state.theta), jnp.sin(state.theta)
    temp = (force + polemass_length * state.theta_dot**2 * sintheta) / total_mass
    thetaacc = (params.gravity * sintheta - costheta * temp) / (
        params.length * (4.0 / 3.0 - params.masspole * costheta**2 / total_mass))
    xacc = temp - polemass_length * thetaacc * costheta / total_mass
    return CartPoleState(x=state.x + params.tau * state.x_dot, x_dot=state.x_dot + params.tau * xacc,
                         theta=state.theta + params.tau * state.theta_dot,
                         theta_dot=state.theta_dot + params.tau * thetaacc)


def observe(state: CartPoleState, params) -> dict[str, jax.Array]:
    return {"state": jnp.stack([state.x, state.x_dot, state.theta, state.theta_dot]).astype(jnp.float32)}


_F32_MAX = float(np.finfo(np.float32).max)
OBSERVATION_SPEC = Dict(state=Box(-np.array([4.8, _F32_MAX, 24 * 2 * math.pi / 360, _F32_MAX]),
                                  np.array([4.8, _F32_MAX, 24 * 2 * math.pi / 360, _F32_MAX]), dtype=jnp.float32))


def balance() -> Task:
    """Keep the pole upright and the cart on the track (Gymnasium's reward and termination)."""

    def failed(physics, params):
        return (jnp.abs(physics.x) > params.x_threshold) | (jnp.abs(physics.theta) > params.theta_threshold)

    def reset(key, physics, outcome, params):
        return outcome.replace(success=~failed(physics, params)), ()

    def update(state, outcome, transition, params):
        terminated = failed(transition.physics, params)
        return outcome.replace(reward=outcome.reward + 1.0, terminated=outcome.terminated | terminated,
                               success=~terminated), state

    return Task(update=update, reset=reset, default_params=lambda: as_float32(BalanceParams()), name="balance",
                has_success=True)


def dynamics() -> Dynamics:
    return Dynamics(init=init, step=step, control_spec=Discrete(2),
                    default_params=lambda: as_float32(CartPoleParams()), timestep=0.02, render=draw_cartpole,
                    name="cartpole")


def sensor() -> Sensor:
    return Sensor(observe=observe, spec=OBSERVATION_SPEC, name="cartpole_state")


DOMAIN = Domain(name="cartpole", dynamics=dynamics, sensor=sensor, tasks={"balance": balance}, time_limit=500,
                tags={"balance": ("benchmark",)})
