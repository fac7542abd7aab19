"""``oracle_point_mass``: PD control of the classic point mass to its goal.

The force is ``k_p (goal - position) - k_d velocity`` per axis, clipped to the action spec, from the
privileged physics (position, velocity) and the goal in ``info.goal``. With the arena's mass of 1 kg and
damping of 1 N s/m, the closed loop (unsaturated) is ``x'' + (1 + k_d) x' + k_p x = k_p goal``: the
defaults ``k_p = 9``, ``k_d = 5`` make it critically damped with natural frequency 3 rad/s.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import make_config, unbounded
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class PointMassOracleConfig:
    """Proportional gain (N/m) on the position error and derivative gain (N s/m) on the velocity."""

    k_p: float = unbounded(9.0)  # N/m: force per metre of position error (goal - position), per axis
    k_d: float = unbounded(5.0)  # N s/m: braking force per m/s of velocity, per axis


def make_point_mass_oracle(config=None) -> Agent:
    """The oracle for ``classic|domain:point_mass`` (task ``reach``)."""
    cfg = make_config(PointMassOracleConfig, config, agent="oracle_point_mass")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        p = privileged.physics
        force = cfg.k_p * (info.goal - p.position) - cfg.k_d * p.velocity
        low = jnp.asarray(state.spec.action.low, jnp.float32)
        high = jnp.asarray(state.spec.action.high, jnp.float32)
        return jnp.clip(force, low, high), state

    return Agent(name="oracle_point_mass", init=init, act=act, privileged=True, made_for=("point_mass",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_point_mass", make_point_mass_oracle, tags=("oracle",))
