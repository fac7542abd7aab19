"""``evaluate`` and ``validate``: every episode of a split, in parallel, in one compiled call."""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.agent import Agent
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset
from jarena.core.types import ArenaParams
from jarena.runners.loop import frozen_step
from jarena.runners.results import EvalResult

PyTree = Any


@functools.lru_cache(maxsize=64)
def _compiled_episodes(agent: Agent, arena: Arena, num: int, max_steps: int, params_axis: int | None):
    """A jitted ``(key, agent_state, params, ids) -> per-episode arrays`` for ``num`` episodes."""

    def episodes(key, agent_state, params, ids):
        state, info = batch_reset(arena, None, num, params, params_axis=params_axis, episodes=ids)
        zeros = jnp.zeros((num,), jnp.float32)
        carry = (state, info, agent_state, jnp.zeros((num,), bool), zeros, jnp.zeros((num,), jnp.int32),
                 jnp.zeros((), jnp.int32))

        def cond(c):
            done, t = c[3], c[6]
            return (t < max_steps) & ~jnp.all(done)

        def body(c):
            state, info, agent_state, done, ret, length, t = c
            state, info, agent_state, _, valid = frozen_step(agent, arena, state, info, agent_state,
                                                             jax.random.fold_in(key, t), params, params_axis, done)
            ret = ret + jnp.where(valid, info.reward, 0.0)
            length = length + valid.astype(jnp.int32)
            return state, info, agent_state, done | info.done, ret, length, t + 1

        state, info, agent_state, done, ret, length, _ = jax.lax.while_loop(cond, body, carry)
        return {"returns": ret, "lengths": length, "successes": info.success, "metrics": info.metrics,
                "done": done}

    return jax.jit(episodes)


def evaluate(agent: Agent, arena: Arena, key: jax.Array | None = None, *, agent_state: PyTree = None,
             params: ArenaParams | None = None, params_axis: int | None = None, split: str = "eval",
             episodes: Any = None, max_steps: int | None = None) -> EvalResult:
    """Runs ``agent`` on every episode of ``split`` (or the given episode ids), all in parallel.

    Each arena runs one episode to its end (terminated or truncated) or ``max_steps`` agent steps; the
    whole evaluation is one compiled ``while_loop`` over a batch of arenas.

    Args:
      agent: any :class:`~jarena.core.agent.Agent`.
      arena: the arena.
      key: PRNG key for the agent's randomness (default ``jax.random.key(0)``).
      agent_state: the agent's state for a batch of N arenas (default: ``agent.init``).
      params, params_axis: arena params, shared (axis ``None``) or per episode (axis 0).
      split: ``eval`` or ``val``.
      episodes: explicit episode ids instead of a split's.
      max_steps: step cap (default: the arena's ``max_episode_steps``).

    Returns:
      An :class:`EvalResult` with per-episode returns, lengths, successes and metrics.
    """
    if split not in ("eval", "val"):
        raise ValueError(f"evaluate runs the fixed 'eval' or 'val' splits, got split={split!r}")
    ids = np.asarray(list(arena.episodes(split)) if episodes is None else episodes, np.int32).reshape(-1)
    if ids.size == 0:
        raise ValueError(f"no episodes to evaluate in split {split!r} of arena {arena.name!r}")
    max_steps = max_steps or arena.max_episode_steps
    if max_steps is None:
        raise ValueError(f"arena {arena.name!r} has no time limit; pass max_steps to evaluate")
    key = jax.random.key(0) if key is None else key
    params = arena.default_params() if params is None else params
    if agent_state is None:
        agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, int(ids.size))
    out = _compiled_episodes(agent, arena, int(ids.size), int(max_steps), params_axis)(
        key, agent_state, params, jnp.asarray(ids))
    out = jax.device_get(out)
    return EvalResult(arena=arena.build_string or arena.name, agent=agent.name, split=split, episodes=ids,
                      returns=np.asarray(out["returns"]), lengths=np.asarray(out["lengths"]),
                      successes=np.asarray(out["successes"]),
                      metrics={k: np.asarray(v) for k, v in out["metrics"].items()})


def validate(agent: Agent, arena: Arena, key: jax.Array | None = None, **kwargs) -> EvalResult:
    """:func:`evaluate` on the validation split."""
    return evaluate(agent, arena, key, split="val", **kwargs)
