"""The agent-arena loop body shared by all runners (pure; runners wrap it in scan or while_loop)."""

from __future__ import annotations

from typing import Any

import jax

from jarena.core.agent import Agent
from jarena.core.arena import Arena
from jarena.core.batching import batch_step
from jarena.core.tree import tree_where
from jarena.core.types import ArenaParams, ArenaState, Info

PyTree = Any


def act_and_step(agent: Agent, arena: Arena, state: ArenaState, info: Info, agent_state: PyTree, key: jax.Array,
                 params: ArenaParams, params_axis: int | None, reset_done: bool
                 ) -> tuple[ArenaState, Info, PyTree, PyTree]:
    """One step of B arenas: the agent acts on ``info``, the arenas step (auto-resetting if asked).

    Returns ``(state, info, agent_state, action)``.
    """
    privileged = arena.privileged(state) if agent.privileged else None
    action, agent_state = agent.act(agent_state, info, key, privileged)
    state, info = batch_step(arena, state, action, params, params_axis=params_axis, reset_done=reset_done)
    agent_state = agent.update(agent_state, info, action)
    if reset_done:
        agent_state = agent.reset(agent_state, info.done)
    return state, info, agent_state, action


def frozen_step(agent: Agent, arena: Arena, state: ArenaState, info: Info, agent_state: PyTree, key: jax.Array,
                params: ArenaParams, params_axis: int | None, done: jax.Array
                ) -> tuple[ArenaState, Info, PyTree, PyTree, jax.Array]:
    """Like :func:`act_and_step` without auto-reset: arenas whose episode ended (``done``, (B,)) keep
    their last state and info. Returns ``(state, info, agent_state, action, valid)``, where ``valid``
    marks the arenas that really stepped."""
    next_state, next_info, agent_state, action = act_and_step(agent, arena, state, info, agent_state, key,
                                                              params, params_axis, reset_done=False)
    return (tree_where(done, state, next_state), tree_where(done, info, next_info), agent_state, action, ~done)
