"""``oracle_pendulum``: energy-based swing-up plus a stabilising controller for classic pendulum.

With ``theta = 0`` upright (as ``Pendulum-v1``), inertia ``I = m l^2 / 3`` and gravity torque
``m g l / 2 sin(theta)``, the energy relative to resting upright is
``E = I theta_dot^2 / 2 + m g l / 2 (cos(theta) - 1)`` and ``dE/dt = theta_dot * u``. Far from upright
the oracle pumps energy, ``u = k_E (-E) theta_dot`` (saturated, kicked from rest); near upright with
little energy error it switches to PD stabilisation ``u = -(k_p theta + k_d theta_dot)``. Torques are
clipped to the action spec.
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import Range, make_config, ranged, unbounded
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class PendulumOracleConfig:
    # k_E of the swing-up torque u = k_E (-E) theta_dot, with E (J) the energy relative to resting upright
    energy_gain: float = unbounded(2.0)
    k_p: float = unbounded(12.0)  # N m/rad: stabilising torque per radian from upright
    k_d: float = unbounded(2.5)  # N m s/rad: stabilising torque per rad/s of angular velocity
    capture_angle: float = ranged(0.6, Range(0, math.pi))  # rad: switch to stabilisation within this angle of upright
    kick: float = unbounded(1.0)  # torque applied when at rest away from upright


def _angle_normalize(x):
    return ((x + jnp.pi) % (2 * jnp.pi)) - jnp.pi


def make_pendulum_oracle(config=None) -> Agent:
    """The oracle for ``classic|domain:pendulum`` with the default physical constants of ``Pendulum-v1``."""
    from jarena.arenas.classic.pendulum import PendulumParams

    cfg = make_config(PendulumOracleConfig, config, agent="oracle_pendulum")
    dp = PendulumParams()

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        p = privileged.physics
        theta, theta_dot = _angle_normalize(p.theta), p.theta_dot
        inertia = dp.m * dp.l**2 / 3.0
        energy = 0.5 * inertia * theta_dot**2 + 0.5 * dp.m * dp.g * dp.l * (jnp.cos(theta) - 1.0)
        direction = jnp.where(jnp.abs(theta_dot) > 1e-3, jnp.sign(theta_dot), 1.0)
        pump = jnp.where(jnp.abs(theta_dot) > 1e-3, cfg.energy_gain * (-energy) * theta_dot, cfg.kick * direction)
        stabilise = -(cfg.k_p * theta + cfg.k_d * theta_dot)
        torque = jnp.where(jnp.abs(theta) < cfg.capture_angle, stabilise, pump)
        low = jnp.asarray(state.spec.action.low, jnp.float32)
        high = jnp.asarray(state.spec.action.high, jnp.float32)
        return jnp.clip(torque[..., None], low, high), state

    return Agent(name="oracle_pendulum", init=init, act=act, privileged=True, made_for=("pendulum",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_pendulum", make_pendulum_oracle, tags=("oracle",))
