"""``perform_parallel``: a batch of arenas stepped in one compiled ``lax.scan``, sharded over devices."""

from __future__ import annotations

import functools
from typing import Any

import jax
import numpy as np
from flax import struct
from jax.sharding import NamedSharding, PartitionSpec

from jarena import distributed
from jarena.core.agent import Agent, check_agent_fits
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset
from jarena.core.types import ArenaParams, ArenaState, Info
from jarena.runners.loop import act_and_step
from jarena.runners.run import check_count

PyTree = Any


@struct.dataclass
class Rollout:
    """The result of :func:`perform_parallel`.

    Attributes:
      state: the arenas' states at the end (leading axis B), to continue from.
      info: the arenas' :class:`Info` at the end (leading axis B), to continue from.
      agent_state: the agent's state at the end, for the B arenas, to continue from.
      infos: per-step :class:`Info`, (T, B, ...), or ``None`` when not recorded.
      actions: per-step actions, (T, B, ...), or ``None`` when not recorded.
    """

    state: ArenaState
    info: Info
    agent_state: PyTree
    infos: Info | None
    actions: PyTree | None


def _mesh(devices: int | str | None):
    """The devices a rollout spans: as asked, else all devices of a multi-process run, else all local ones."""
    if devices is None:
        devices = "all" if jax.process_count() > 1 else len(jax.local_devices())
    return distributed.mesh(devices)


def _arena_sharding(mesh, num_arenas: int):
    count = mesh.devices.size
    if count < 2:
        return None
    if num_arenas % count:
        raise ValueError(f"perform_parallel shards arenas over {count} devices; num_arenas={num_arenas} must be a "
                         f"multiple of {count}")
    return NamedSharding(mesh, PartitionSpec(distributed.AXIS))


def _constrain(tree, sharding):
    if sharding is None:
        return tree
    return jax.tree_util.tree_map(
        lambda x: jax.lax.with_sharding_constraint(x, sharding) if getattr(x, "ndim", 0) >= 1 else x, tree)


@functools.lru_cache(maxsize=64)
def _compiled(agent: Agent, arena: Arena, num_arenas: int, num_steps: int, params_axis: int | None,
              record: bool, mesh, key_impl):
    sharding = _arena_sharding(mesh, num_arenas)

    def rollout(key_data, start, agent_state, params):
        key = jax.random.wrap_key_data(key_data, impl=key_impl)
        reset_key, act_key = jax.random.split(key)
        if start is None:
            state, info = batch_reset(arena, reset_key, num_arenas, params, params_axis=params_axis)
        else:
            state, info = start
        state, info = _constrain((state, info), sharding)

        def body(carry, t):
            state, info, agent_state = carry
            state, info, agent_state, action = act_and_step(agent, arena, state, info, agent_state,
                                                            jax.random.fold_in(act_key, t), params, params_axis,
                                                            reset_done=True)
            state, info = _constrain((state, info), sharding)
            return (state, info, agent_state), ((info, action) if record else None)

        (state, info, agent_state), out = jax.lax.scan(body, (state, info, agent_state), np.arange(num_steps))
        infos, actions = out if record else (None, None)
        return Rollout(state=state, info=info, agent_state=agent_state, infos=infos, actions=actions)

    return jax.jit(rollout)


def perform_parallel(agent: Agent, arena: Arena, key: jax.Array, num_arenas: int, num_steps: int, *,
                     params: ArenaParams | None = None, params_axis: int | None = None,
                     agent_state: PyTree = None, start: tuple[ArenaState, Info] | None = None,
                     record: bool = True, devices: int | str | None = None) -> Rollout:
    """Steps ``num_arenas`` arenas for ``num_steps`` agent steps with auto-reset, in one compiled call.

    The arena batch is sharded over ``devices`` (``num_arenas`` must divide evenly): by default all local
    devices, or in a multi-process run (:func:`jarena.distributed.initialize`) all devices of all processes,
    whose results are then global arrays (:func:`jarena.distributed.fetch` gathers them to the host).

    Args:
      agent: the agent to run.
      arena: the arena to run it in.
      key: PRNG key for resets and the agent.
      num_arenas: batch size B.
      num_steps: agent steps T.
      params: arena params, shared or per arena (see ``params_axis``).
      params_axis: ``None`` (params shared) or ``0`` (one per arena).
      agent_state: the agent's state for B arenas (default: ``agent.init``).
      start: ``(state, info)`` to continue from (e.g. a previous rollout's), instead of fresh resets.
      record: return per-step infos and actions (T, B, ...); off saves memory for long runs.
      devices: ``"all"``, a device count, or ``None`` (the default above); see :func:`jarena.distributed.mesh`.

    Raises:
      ValueError: ``num_arenas`` or ``num_steps`` < 1.
      AgentArenaMismatch: the agent does not fit the arena (checked before compiling).
    """
    num_arenas = check_count(num_arenas, "num_arenas", "perform_parallel")
    num_steps = check_count(num_steps, "num_steps", "perform_parallel")
    check_agent_fits(agent, arena)
    params = arena.default_params() if params is None else params
    if agent_state is None:
        agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, num_arenas)
    else:
        agent_state = agent.batch_state(agent_state, num_arenas)
    mesh = _mesh(devices)
    if jax.process_count() > 1:  # process-local values (the same in every process) enter as host values
        agent_state, params, start = (_host_unless_global(t) for t in (agent_state, params, start))
    fn = _compiled(agent, arena, num_arenas, num_steps, params_axis, bool(record), mesh, jax.random.key_impl(key))
    with distributed.tracing_on(mesh):  # lazy auto-resets decide per device (jarena.core.batching)
        return fn(np.asarray(jax.random.key_data(key)), start, agent_state, params)


def _host_unless_global(tree):
    """Process-local device arrays as host arrays; arrays spanning processes (a previous rollout's) as they are."""
    return jax.tree_util.tree_map(
        lambda x: x if not isinstance(x, jax.Array) or not x.is_fully_addressable else distributed.fetch(x), tree)
