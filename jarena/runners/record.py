"""``record_video``: run an agent on a few episodes and write their video (one file, tiled if several).

    import jarena, jarena_agents
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup")
    jarena.record_video(jarena_agents.build_agent("random"), arena, "swingup.mp4", episode=0)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jarena.core.agent import Agent
from jarena.core.arena import Arena
from jarena.core.types import ArenaParams
from jarena.render.record import check_video, film, resolve_path
from jarena.render.video import VideoOptions
from jarena.runners.evaluate import run_episodes
from jarena.runners.results import EvalResult

PyTree = Any


@dataclasses.dataclass(frozen=True)
class Recording:
    """A written video: its ``path``, number of ``frames``, ``fps``, and the filmed episodes' ``result``."""

    path: Path
    frames: int
    fps: float
    result: EvalResult


def record_video(agent: Agent, arena: Arena, path: str | Path, episode: int | Sequence[int] = 0, *,
                 key: jax.Array | None = None, agent_state: PyTree = None, params: ArenaParams | None = None,
                 params_axis: int | None = None, width: int = 320, height: int = 240, camera: int | str = -1,
                 max_steps: int | None = None, fps: float | None = None, columns: int | None = None,
                 format: str | None = None) -> Recording:
    """Runs ``agent`` on one or a few episodes and writes their video (several episodes: one grid video).

    The episodes run as in :func:`jarena.evaluate` (in parallel, in one compiled ``while_loop`` that also
    keeps the physics states on device); frames are rendered on the host afterwards, every ``stride``-th
    step for fast arenas (see :func:`jarena.render.video.playback`), until the longest episode ends.

    Args:
      agent: the agent to film.
      arena: the arena to film it in; it must render (:func:`jarena.render.can_render`).
      path: the video file, ``.mp4`` or ``.gif`` (a path without a suffix gets ``format``'s).
      episode: an episode id or a sequence of them (``0 .. n - 1`` are the eval split's).
      key: PRNG key of the agent's randomness (default ``jax.random.key(0)``).
      agent_state: the agent's state for a batch of ``len(episodes)`` arenas (default ``agent.init``).
      params: arena params, shared or per episode (see ``params_axis``).
      params_axis: ``None`` (params shared) or ``0`` (one per episode).
      width: frame width in pixels per episode.
      height: frame height in pixels per episode.
      camera: the camera (MuJoCo arenas).
      max_steps: step cap (default: the arena's ``max_episode_steps``).
      fps: playback rate (default: real time).
      columns: grid columns for several episodes (default ``ceil(sqrt(n))``).
      format: ``mp4`` or ``gif`` when ``path`` has no suffix.

    Returns:
      A :class:`Recording` with the path written, frame count, fps and the episodes' results.
    """
    options = VideoOptions(width=width, height=height, camera=camera, fps=fps, format=format, columns=columns)
    path = resolve_path(path, options)
    check_video(arena, options, params, params_axis)
    ids = np.atleast_1d(np.asarray(episode, np.int64)).reshape(-1)
    result, physics = run_episodes(agent, arena, key, agent_state=agent_state, params=params,
                                   params_axis=params_axis, episodes=ids, max_steps=max_steps, filmed=int(ids.size))
    frames, fps = film(arena, physics, range(ids.size), int(result.lengths.max()) + 1, path, options, params,
                        params_axis)
    return Recording(path=path, frames=frames, fps=fps, result=result)
