"""``run``: one trial of an agent in an arena, returning every step's information and action."""

from __future__ import annotations

import functools
import operator
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.agent import Agent, check_agent_fits
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset
from jarena.core.episodes import check_episode_ids
from jarena.core.types import ArenaParams, Info
from jarena.render.record import check_video, write_episodes
from jarena.runners.loop import frozen_step

PyTree = Any


@struct.dataclass
class Trajectory:
    """One episode, step by step (leaves have a leading time axis T = max_steps).

    Attributes:
      initial: the :class:`Info` after reset (no time axis).
      infos: the :class:`Info` after each step, (T, ...).
      actions: the agent's action at each step, (T, ...).
      valid: bool (T,), the steps that belong to the episode (False after it ended).
    """

    initial: Info
    infos: Info
    actions: PyTree
    valid: jax.Array

    @property
    def length(self) -> jax.Array:
        return jnp.sum(self.valid)

    @property
    def episode_return(self) -> jax.Array:
        return jnp.sum(jnp.where(self.valid, self.infos.reward, 0.0))


def check_count(value: Any, name: str, where: str) -> int:
    """``value`` as an int if it is an integer >= 1; else a ValueError naming ``name`` and the valid range."""
    try:
        count = operator.index(value)
    except TypeError:
        count = None
    if count is None or count < 1:
        raise ValueError(f"{where}: {name} must be an integer >= 1, got {value!r}")
    return count


def _squeeze(tree, axis):
    return jax.tree_util.tree_map(lambda x: jnp.squeeze(x, axis), tree)


@functools.lru_cache(maxsize=64)
def _compiled_run(agent: Agent, arena: Arena, max_steps: int, with_episode: bool, film: bool = False):
    """A jitted ``(key, episode, agent_state, params) -> (Trajectory, physics)``; ``physics`` holds the
    arena's physics states (max_steps + 1, 1, ...), the reset state first, when ``film``, else ``None``."""

    def trial(key, episode, agent_state, params):
        reset_key, act_key = jax.random.split(key)
        state, info = batch_reset(arena, reset_key, 1, params,
                                  episodes=jnp.reshape(episode, (1,)) if with_episode else None)
        initial = info

        def body(carry, t):
            state, info, agent_state, done = carry
            state, info, agent_state, action, valid = frozen_step(
                agent, arena, state, info, agent_state, jax.random.fold_in(act_key, t), params, None, done)
            return (state, info, agent_state, done | info.done), (info, action, valid,
                                                                   state.physics if film else None)

        carry = (state, info, agent_state, jnp.zeros((1,), bool))
        _, (infos, actions, valid, physics) = jax.lax.scan(body, carry, jnp.arange(max_steps))
        if film:
            physics = jax.tree_util.tree_map(lambda x0, xs: jnp.concatenate([x0[None], xs]), state.physics, physics)
        return Trajectory(initial=_squeeze(initial, 0), infos=_squeeze(infos, 1), actions=_squeeze(actions, 1),
                          valid=valid[:, 0]), physics

    return jax.jit(trial)


def run(agent: Agent, arena: Arena, key: jax.Array, *, episode: int | None = None,
        params: ArenaParams | None = None, agent_state: PyTree = None, max_steps: int | None = None,
        video: str | Path | None = None, video_options: Any = None) -> Trajectory:
    """Runs one episode (a training episode drawn from ``key``, or ``episode``) in one compiled call.

    Args:
      agent: the agent to run.
      arena: the arena to run it in.
      key: PRNG key (episode draw and the agent's randomness).
      episode: an episode id, e.g. ``arena.episodes("eval")[3]`` (in ``[0, 2^31)``).
      params: arena params.
      agent_state: the agent's state for a batch of one arena (default: ``agent.init``).
      max_steps: length of the recorded trajectory, >= 1 (default: the arena's ``max_episode_steps``).
      video: write a video of the episode to this path (``.mp4`` or ``.gif``): the scan also keeps the
        physics states on device and the frames are rendered on the host afterwards. The arena must
        render (``jarena.render.can_render``); the trajectory is the same as without.
      video_options: a :class:`jarena.render.VideoOptions` (frame size, camera, fps).

    Raises:
      ValueError: ``max_steps`` < 1 or an episode id out of range.
      AgentArenaMismatch: the agent does not fit the arena (checked before compiling).
    """
    check_episode_ids(episode, "run: episode")
    if max_steps is not None:
        check_count(max_steps, "max_steps", "run")
    if video is not None:
        check_video(arena, video_options, params)  # fails before compiling when the arena cannot render
    max_steps = max_steps or arena.max_episode_steps
    if max_steps is None:
        raise ValueError(f"arena {arena.name!r} has no time limit; pass max_steps to run")
    check_agent_fits(agent, arena)
    params = arena.default_params() if params is None else params
    if agent_state is None:
        agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, 1)
    episode_arg = jnp.asarray(0 if episode is None else episode, jnp.int32)
    trajectory, physics = _compiled_run(agent, arena, int(max_steps), episode is not None, video is not None)(
        key, episode_arg, agent_state, params)
    if video is not None:
        write_episodes(arena, physics, [int(trajectory.length)], [video], video_options, params=params)
    return trajectory
