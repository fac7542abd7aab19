"""``collect``: run any agent on a batch of arenas and store its trajectories in a dataset.

Agent-Arena's data-collection program in a few lines::

    arena = jarena.build_arena("classic|domain:pendulum,task:swingup")
    agent = jarena_agents.build_agent("oracle_pendulum")
    dataset = jarena.TrajectoryDataset("demos", "a", **jarena.data.configs_for(arena))
    jarena.collect(agent, arena, dataset, 100, key=jax.random.key(0))

The arenas step in compiled chunks of ``chunk_steps`` steps (:func:`jarena.perform_parallel`, with
auto-reset); between chunks the host cuts finished episodes out of the recorded steps and appends
them to the dataset in one commit per chunk, and updates a progress bar.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset
from jarena.core.types import ArenaParams
from jarena.data.dataset import TrajectoryDataset
from jarena.data.schema import Field, spec_fields
from jarena.runners.parallel import perform_parallel

Observe = Callable[[dict[str, jax.Array]], dict[str, jax.Array]]


DEFAULT_CHUNK_STEPS = 100
"""Agent steps per compiled chunk of :func:`collect`, unless fewer finish every episode it needs."""


def configs_for(arena: Arena, observe: Observe | None = None, compression: str | None = None) -> dict[str, dict]:
    """Dataset configs (``obs_config``, ``act_config``, ``goal_config``) for ``arena``'s trajectories.

    Args:
      arena: the arena whose observations, actions and goals are stored.
      observe: the observation transform given to :func:`collect` (e.g. :func:`resize_images`), if any.
      compression: codec for every observation field (``None``: raw).
    """
    observation = jax.eval_shape(lambda: arena.reset(jax.random.key(0))[1].observation)
    if observe is not None:
        observation = jax.eval_shape(observe, observation)
    obs_config = {k: Field(v.shape, np.dtype(v.dtype).name, compression=compression) for k, v in observation.items()}
    goal_config = {"goal": Field((arena.goal_dim,), "float32")} if arena.goal_dim else {}
    return dict(obs_config=obs_config, act_config=spec_fields(arena.action_spec, "action"), goal_config=goal_config)


def resize_images(size: tuple[int, int], keys: tuple[str, ...] | None = None, method: str = "linear") -> Observe:
    """An observation transform resizing image fields (H, W, C) to ``size``; integer images keep their dtype.

    ``keys`` names the fields to resize (default: every field with three axes).
    """
    height, width = (int(s) for s in size)

    def observe(observation):
        out = dict(observation)
        for k, v in observation.items():
            if (keys is None and v.ndim == 3) or (keys is not None and k in keys):
                resized = jax.image.resize(v.astype(jnp.float32), (height, width, v.shape[-1]), method)
                if jnp.issubdtype(v.dtype, jnp.integer):
                    info = jnp.iinfo(v.dtype)
                    resized = jnp.clip(jnp.round(resized), info.min, info.max)
                out[k] = resized.astype(v.dtype)
        return out

    return observe


def _chunk_to_host(start_info, rollout, observe: Observe | None) -> dict[str, Any]:
    """The chunk's steps as numpy arrays (T, B, ...): what the agent saw, did, and got."""
    def before(first, rest):
        return jnp.concatenate([first[None], rest[:-1]])

    infos = rollout.infos
    observation = jax.tree_util.tree_map(before, start_info.observation, infos.observation)
    following = infos.final.observation
    if observe is not None:
        observe_all = jax.vmap(jax.vmap(observe))
        observation, following = observe_all(observation), observe_all(following)
    return distributed.fetch(dict(observation=observation, next_observation=following, action=rollout.actions,
                                  reward=infos.reward, terminated=infos.terminated, truncated=infos.truncated,
                                  goal=before(start_info.goal, infos.goal),
                                  episode=before(start_info.episode, infos.episode)))


def _take(tree, index):
    return jax.tree_util.tree_map(lambda x: x[index], tree)


def _concat(parts):
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)


class _Episodes:
    """Cuts per-arena step streams into finished episodes, keeping unfinished ones across chunks."""

    def __init__(self, num_arenas: int, has_goal: bool):
        self.pending: list[list[dict]] = [[] for _ in range(num_arenas)]
        self.has_goal = has_goal

    def finished(self, chunk: dict[str, Any]) -> list[dict[str, Any]]:
        """Trajectories (``add_trajectory`` arguments) that ended in ``chunk``, in order of their end."""
        done = chunk["terminated"] | chunk["truncated"]
        out = []
        for b in range(done.shape[1]):
            arena_steps = _take(chunk, (slice(None), b))
            start = 0
            for end in np.flatnonzero(done[:, b]):
                steps = _concat(self.pending[b] + [_take(arena_steps, slice(start, end + 1))])
                self.pending[b], start = [], end + 1
                out.append((end, b, self._trajectory(steps)))
            if start < done.shape[0]:
                self.pending[b].append(_take(arena_steps, slice(start, None)))
        return [t for _, _, t in sorted(out, key=lambda x: x[:2])]

    def _trajectory(self, steps: dict[str, Any]) -> dict[str, Any]:
        observations = jax.tree_util.tree_map(lambda o, n: np.concatenate([o, n[-1:]]), steps["observation"],
                                              steps["next_observation"])
        return dict(observations=observations, actions=steps["action"],
                    goal=steps["goal"][0] if self.has_goal else None, rewards=steps["reward"],
                    terminated=steps["terminated"], truncated=steps["truncated"], episode=int(steps["episode"][0]))


def collect(agent: Agent, arena: Arena, dataset: TrajectoryDataset | None, n_trajectories: int, *, key: jax.Array,
            num_arenas: int | None = None, params: ArenaParams | None = None, chunk_steps: int | None = None,
            observe: Observe | None = None, progress: bool = True, devices: int | str | None = None) -> list[int]:
    """Runs ``agent`` on a batch of ``arena`` and appends ``n_trajectories`` finished episodes to ``dataset``.

    Args:
      agent: the agent to run.
      arena: the arena to run it in (training episodes drawn from ``key``, auto-reset as they end).
      dataset: an open, writable :class:`TrajectoryDataset` whose configs fit (see :func:`configs_for`). In a
        multi-process run (:func:`jarena.distributed.initialize`) every process calls ``collect`` alike and
        only process 0 opens the dataset and writes to it; the others pass ``None``.
      n_trajectories: episodes to store (the first to finish; unfinished ones at the end are dropped).
      key: PRNG key; the stored trajectories are a pure function of it (and the arguments).
      num_arenas: arenas run in parallel (default ``min(n_trajectories, 64)``).
      params: arena params (shared by all arenas).
      chunk_steps: agent steps per compiled chunk; host work happens between chunks. Default: 100, or fewer
        when fewer steps finish every episode needed (each arena's share of ``n_trajectories`` times the
        arena's ``max_episode_steps``), so expensive agents (a cloth oracle that simulates its proposals)
        run no step that cannot be stored.
      observe: a traceable transform of each observation dict before storing (e.g. :func:`resize_images`).
      progress: show a progress bar.
      devices: the arenas are split over these devices (:func:`jarena.perform_parallel`'s ``devices``; by
        default all local ones, or all of a multi-process run); ``num_arenas`` must divide evenly.

    Returns:
      The indices of the stored trajectories in ``dataset`` (``[]`` in processes that do not write).
    """
    if arena.max_episode_steps is None:
        raise ValueError(f"arena {arena.name!r} has no time limit, so its episodes may never end; "
                         f"add one with jarena.tasks.time_limit before collecting")
    num_arenas = int(num_arenas or min(n_trajectories, 64))
    if chunk_steps is None:
        chunk_steps = min(DEFAULT_CHUNK_STEPS, -(-n_trajectories // num_arenas) * int(arena.max_episode_steps))
    if n_trajectories < 1 or chunk_steps < 1:
        raise ValueError(f"n_trajectories and chunk_steps must be positive, got {n_trajectories}, {chunk_steps}")
    main = distributed.is_main_process()
    if (dataset is None) == main:
        raise ValueError("collect: pass the dataset in process 0 (the process that writes) and None in the others, "
                         f"got {'None' if dataset is None else 'a dataset'} in process {jax.process_index()}")
    params = arena.default_params() if params is None else params
    key_reset, key_agent, key_run = jax.random.split(key, 3)
    state, info = jax.jit(lambda k, p: batch_reset(arena, k, num_arenas, p))(key_reset, params)
    agent_state = agent.init(key_agent, arena.spec, num_arenas)
    episodes = _Episodes(num_arenas, has_goal=bool(dataset.schema.goal) if main else False)
    stored: list[int] = []
    done = 0
    with tqdm(total=n_trajectories, desc=f"collect {arena.name}", unit="traj", disable=not (progress and main)) as bar:
        chunk = 0
        while done < n_trajectories:
            rollout = perform_parallel(agent, arena, jax.random.fold_in(key_run, chunk), num_arenas, chunk_steps,
                                       params=params, agent_state=agent_state, start=(state, info),
                                       devices=devices)
            finished = episodes.finished(_chunk_to_host(info, rollout, observe))
            finished = finished[:n_trajectories - done]
            if main:
                stored += dataset.add_trajectories(finished)
            done += len(finished)
            bar.update(len(finished))
            state, info, agent_state, chunk = rollout.state, rollout.info, rollout.agent_state, chunk + 1
    return stored

