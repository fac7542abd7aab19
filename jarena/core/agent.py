"""The agent protocol: a frozen bundle of pure functions whose state is batched over arenas.

Every function works on a batch of B arenas at once (the batch axis replaces Agent-Arena's per-arena-id
dictionaries): ``info`` leaves have a leading axis B, actions are returned with a leading axis B, and
the agent state holds whatever per-arena values the agent keeps (recurrent belief, planner warm start,
phase). Agents built by :func:`jarena_agents.build_agent` implement it; runners accept any ``Agent``.

Before compiling, runners call :func:`check_agent_fits`: an agent that does not fit the arena (made
for other arenas, or whose ``init``/``act`` fail on its spec or state) raises :class:`AgentArenaMismatch`
naming both and what differs, instead of an error from deep inside the trace.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from jarena.core.arena import Arena
from jarena.core.types import Info

PyTree = Any


def _keep_state(state, *args):
    return state


def _all_false(state, info: Info) -> jax.Array:
    return jnp.zeros(info.reward.shape, bool)


def _phase_zero(state, info: Info) -> jax.Array:
    return jnp.zeros(info.reward.shape, jnp.int32)


def _same_state(state, num_arenas: int):
    return state


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
      success: ``(state, info) -> bool (B,)``; the agent's own view of success.
      terminate: ``(state, info) -> bool (B,)``; whether the agent wants to stop.
      phase: ``(state, info) -> int32 (B,)``; the agent's current phase (e.g. for scripted oracles).
      batch_state: ``(state, num_arenas) -> state``; fits a given state (a trained policy's, from
        ``TrainableAgent.policy``) to a batch of B arenas: agents with per-arena memory (a recurrent
        belief) allocate it here, others return the state as it is. Runners call it on every
        ``agent_state`` they are given; a state already fitted to B arenas is returned unchanged.
      privileged: whether ``act`` needs privileged simulator state (oracles, planners).
      config: the config the agent was built with (not part of equality or hashing).
      made_for: names of the dynamics (``arena.dynamics.name``) the agent is written for, e.g.
        ``("cartpole",)`` for a scripted oracle reading the classic cartpole's physics; empty: any arena
        its functions fit. Not part of equality or hashing.
    """

    name: str
    init: Callable[[jax.Array, Any, int], PyTree]
    act: Callable[[PyTree, Info, jax.Array, Any], tuple[PyTree, PyTree]]
    reset: Callable[[PyTree, jax.Array], PyTree] = _keep_state
    update: Callable[[PyTree, Info, PyTree], PyTree] = _keep_state
    success: Callable[[PyTree, Info], jax.Array] = _all_false
    terminate: Callable[[PyTree, Info], jax.Array] = _all_false
    phase: Callable[[PyTree, Info], jax.Array] = _phase_zero
    batch_state: Callable[[PyTree, int], PyTree] = _same_state
    privileged: bool = False
    config: Any = dataclasses.field(default=None, compare=False, hash=False)
    made_for: tuple[str, ...] = dataclasses.field(default=(), compare=False, hash=False)

    def check_fits(self, arena: Arena) -> None:
        """:func:`check_agent_fits` of this agent and ``arena`` (cached)."""
        check_agent_fits(self, arena)


class AgentArenaMismatch(ValueError):
    """An agent does not fit an arena (made for other arenas, or its functions fail on the arena's spec)."""


@functools.lru_cache(maxsize=64)
def check_agent_fits(agent: Agent, arena: Arena) -> None:
    """Raises :class:`AgentArenaMismatch` unless ``agent`` fits ``arena``; cached per (agent, arena).

    Two checks, before anything compiles:

    - the arena's dynamics must be one of ``agent.made_for``, when the agent declares any (the family:
      the trace below cannot tell, as JAX clamps out-of-range indices instead of failing);
    - one abstract step on a batch of one arena must trace under ``jax.eval_shape`` (shapes only: nothing is
      compiled or run): ``init``, ``act`` on the reset's info (with the privileged state if the agent asks
      for it), its action checked against the action spec (``Spec.validate``, what ``step`` does first), and
      ``update`` with an info of the reset's shapes (the runners' loops carry one info through resets and
      steps, so a step's info has the same). Neither ``reset`` nor ``step`` is traced again for this: the
      reset's shapes are ``arena.reset_shapes`` (traced once per arena, for the spec too).
    """
    if agent.made_for and arena.dynamics.name not in agent.made_for:
        made_for = " or ".join(map(repr, agent.made_for))
        raise AgentArenaMismatch(_mismatch(agent, arena, f"{agent.name} is made for arenas with {made_for} "
                                                         f"dynamics; got {arena.name}, whose dynamics are "
                                                         f"{arena.dynamics.name!r}"))
    spec = arena.spec
    try:
        one = jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct((1,) + x.shape, x.dtype), arena.reset_shapes)
        jax.eval_shape(lambda state, info: _one_step(agent, arena, spec, state, info), *one)
    except Exception as e:  # any failure of the agent's functions on this arena is the mismatch
        raise AgentArenaMismatch(_mismatch(agent, arena, f"{type(e).__name__}: {e}")) from e


def _one_step(agent: Agent, arena: Arena, spec: Any, state: PyTree, info: Info) -> PyTree:
    """One runner step on a batch of one arena from its reset ``state`` and ``info`` (leading axis 1): what
    :func:`check_agent_fits` traces."""
    agent_state = agent.init(jax.random.key(1), spec, 1)
    privileged = arena.privileged(state) if agent.privileged else None
    action, agent_state = agent.act(agent_state, info, jax.random.key(2), privileged)
    jax.vmap(lambda a: arena.action_spec.validate(a, "action"))(action)
    return agent.update(agent_state, info, action)


def _mismatch(agent: Agent, arena: Arena, reason: str) -> str:
    return (f"agent {agent.name!r} does not fit arena {arena.build_string or arena.name!r}: {reason}\n"
            f"  the arena's observation spec: {arena.observation_spec}\n"
            f"  the arena's action spec: {arena.action_spec}")
