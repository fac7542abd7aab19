"""The agent protocol: a frozen bundle of pure functions whose state is batched over arenas.

Every function works on a batch of B arenas at once (the batch axis replaces Agent-Arena's per-arena-id
dictionaries): ``info`` leaves have a leading axis B, actions are returned with a leading axis B, and
the agent state holds whatever per-arena values the agent keeps (recurrent belief, planner warm start,
phase). Agents built by :func:`jarena_agents.build_agent` implement it; runners accept any ``Agent``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from jarena.core.types import Info

PyTree = Any


def _keep_state(state, *args):
    return state


def _all_false(state, info: Info) -> jax.Array:
    return jnp.zeros(info.reward.shape, bool)


def _phase_zero(state, info: Info) -> jax.Array:
    return jnp.zeros(info.reward.shape, jnp.int32)


@dataclasses.dataclass(frozen=True)
class Agent:
    """An agent.

    Attributes:
      name: registry name.
      init: ``(key, arena_spec, num_arenas) -> state``.
      act: ``(state, info, key, privileged) -> (action, state)``; ``info`` batched over B arenas;
        ``privileged`` is ``arena.privileged(arena_state)`` (batched) for agents that declare
        ``privileged=True``, else ``None``.
      reset: ``(state, mask) -> state``; resets the per-arena state where ``mask`` (bool, (B,)) is set.
      update: ``(state, info, action) -> state``; updates internal state after a step.
      success, terminate: ``(state, info) -> bool (B,)``; the agent's own view of success, and whether
        it wants to stop.
      phase: ``(state, info) -> int32 (B,)``; the agent's current phase (e.g. for scripted oracles).
      privileged: whether ``act`` needs privileged simulator state (oracles, planners).
      config: the config the agent was built with (not part of equality or hashing).
    """

    name: str
    init: Callable[[jax.Array, Any, int], PyTree]
    act: Callable[[PyTree, Info, jax.Array, Any], tuple[PyTree, PyTree]]
    reset: Callable[[PyTree, jax.Array], PyTree] = _keep_state
    update: Callable[[PyTree, Info, PyTree], PyTree] = _keep_state
    success: Callable[[PyTree, Info], jax.Array] = _all_false
    terminate: Callable[[PyTree, Info], jax.Array] = _all_false
    phase: Callable[[PyTree, Info], jax.Array] = _phase_zero
    privileged: bool = False
    config: Any = dataclasses.field(default=None, compare=False, hash=False)
