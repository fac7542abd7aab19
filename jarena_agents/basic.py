"""Agents without learning: ``random`` (uniform valid actions) and ``no_op`` (no actuation)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.agent import Agent
from jarena.core.arena import ArenaSpec
from jarena_agents.config import make_config
from jarena_agents.registry import register_agent


@struct.dataclass
class SpecState:
    """Agent state of the stateless agents: the arena spec, as static metadata."""

    spec: ArenaSpec = struct.field(pytree_node=False)


@dataclasses.dataclass(frozen=True)
class RandomConfig:
    pass


def _batch_size(info) -> int:
    return info.reward.shape[0]


def make_random(config=None) -> Agent:
    """Acts uniformly at random in the action spec, independently per arena."""
    make_config(RandomConfig, config, agent="random")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged=None):
        keys = jax.random.split(key, _batch_size(info))
        return jax.vmap(state.spec.action.sample)(keys), state

    return Agent(name="random", init=init, act=act, config={})


def make_no_op(config=None) -> Agent:
    """Applies the arena's no-op action (no actuation) in every arena."""
    make_config(RandomConfig, config, agent="no_op")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged=None):
        no_op = jax.tree_util.tree_map(jnp.asarray, state.spec.no_op)
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (_batch_size(info),) + x.shape), no_op), state

    return Agent(name="no_op", init=init, act=act, config={})


register_agent("random", make_random, tags=("baseline",))
register_agent("no_op", make_no_op, tags=("baseline",))
