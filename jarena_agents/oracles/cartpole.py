"""``oracle_cartpole``: a scripted linear-feedback controller for classic cartpole balance.

Pushes right when ``k . (x, x_dot, theta, theta_dot) > 0`` (bang-bang on a stabilising linear
feedback), reading the privileged physics state. Balances every evaluation episode for the full 500
steps of ``CartPole-v1``.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import make_config, unbounded
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class CartPoleOracleConfig:
    """Feedback gains on cart position, cart velocity, pole angle and pole angular velocity."""

    k_x: float = unbounded(0.1)  # per m of cart position (pushes right while the weighted sum is > 0)
    k_x_dot: float = unbounded(0.3)  # per m/s of cart velocity
    k_theta: float = unbounded(2.0)  # per rad of pole angle (0: upright)
    k_theta_dot: float = unbounded(0.5)  # per rad/s of pole angular velocity


def make_cartpole_oracle(config=None) -> Agent:
    cfg = make_config(CartPoleOracleConfig, config, agent="oracle_cartpole")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        p = privileged.physics
        u = cfg.k_x * p.x + cfg.k_x_dot * p.x_dot + cfg.k_theta * p.theta + cfg.k_theta_dot * p.theta_dot
        return (u > 0).astype(jnp.int32), state

    return Agent(name="oracle_cartpole", init=init, act=act, privileged=True, made_for=("cartpole",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_cartpole", make_cartpole_oracle, tags=("oracle",))
