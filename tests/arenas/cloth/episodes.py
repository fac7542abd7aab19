"""Cloth episodes that several agents run, with the reset and the step compiled once for all of them.

``jarena.evaluate`` compiles each agent's whole evaluation (the arena's reset, its step and the agent) into one
program; on a CPU a cloth's reset and step are most of that compile (each several seconds), so tests that compare
agents on the same episodes reset them once and share one compiled step, and only each agent's act is compiled
apart. The loop is evaluate's: params as arguments, the agent's state from ``agent.init(fold_in(key, 0x1A1))``, its
key folded with the step, and an episode that ended keeps its last state and info.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.batching import batch_reset, batch_step
from jarena.core.tree import tree_where


class Episodes:
    """The arena's ``episodes`` (ids), reset once (or from ``start``, their ``(state, info)``) for every agent run
    on them with :meth:`run`."""

    def __init__(self, arena, episodes, start=None):
        self.arena, self.params = arena, arena.default_params()
        self.ids = jnp.asarray(np.asarray(episodes, np.int32).reshape(-1))
        num = int(self.ids.shape[0])
        self.reset = jax.jit(lambda ids, params: batch_reset(arena, None, num, params, episodes=ids))
        self.start = self.reset(self.ids, self.params) if start is None else start

        @jax.jit
        def step(state, info, action, done, params):
            next_state, next_info = batch_step(arena, state, action, params, reset_done=False)
            state, info = tree_where(done, state, next_state), tree_where(done, info, next_info)
            return state, info, done | info.done

        self.step = step

    def run(self, agent, key: jax.Array | None = None):
        """The last info of each episode of ``agent`` (``jarena.evaluate``'s default key: ``jax.random.key(0)``)."""
        arena = self.arena
        key = jax.random.key(0) if key is None else key
        agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, int(self.ids.shape[0]))

        @jax.jit
        def act(state, info, agent_state, key):
            return agent.act(agent_state, info, key, arena.privileged(state) if agent.privileged else None)

        update = jax.jit(agent.update)
        (state, info), done = self.start, jnp.zeros(self.ids.shape, bool)
        for t in range(arena.max_episode_steps):
            if bool(done.all()):
                break
            action, agent_state = act(state, info, agent_state, jax.random.fold_in(key, t))
            state, info, done = self.step(state, info, action, done, self.params)
            agent_state = update(agent_state, info, action)
        return info
