"""Videos of episodes: run them with the runners (physics states kept on device by the compiled loop),
then render the frames on the host and write MP4 or GIF files.

    import jarena, jarena_agents
    from jarena.render import record_video
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup")
    record_video(jarena_agents.build_agent("random"), arena, "swingup.mp4", episode=0)
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
from jarena.render.frames import RenderError, render_trajectory, renderer
from jarena.render.video import VideoOptions, playback, video_path, write_video
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


def _resolve(path: str | Path, options: VideoOptions) -> Path:
    path = Path(path)
    return video_path(path, options.format or (None if path.suffix else "mp4"))[0]


def check_video(arena: Arena, options: VideoOptions | None = None, params: ArenaParams | None = None,
                params_axis: int | None = None) -> None:
    """Fails early, before any rollout is compiled, when ``arena`` cannot render, or not with ``options``
    (frame size, camera): renders one frame of a fresh physics state (``dynamics.init``)."""
    render = renderer(arena)
    options = options or VideoOptions()
    dynamics_params = (arena.default_params() if params is None else params).dynamics
    if params_axis is not None:  # per-arena params: probe with the first arena's
        dynamics_params = jax.tree_util.tree_map(lambda x: x[0], dynamics_params)
    probe = jax.device_get(arena.dynamics.init(jax.random.key(0), dynamics_params))
    try:
        render(probe, jax.device_get(dynamics_params), width=options.width, height=options.height,
               camera=options.camera)
    except ValueError as e:
        raise RenderError(f"arena {arena.build_string or arena.name!r} cannot render a {options.width} x "
                          f"{options.height} frame from camera {options.camera!r}: {e}") from None
    except Exception as e:  # mujoco.FatalError and GL errors: no usable OpenGL context in this process
        import os
        raise RenderError(f"arena {arena.build_string or arena.name!r} cannot render here: {type(e).__name__}: {e}. "
                          "MuJoCo chooses its OpenGL backend when first imported (MUJOCO_GL is "
                          f"{os.environ.get('MUJOCO_GL')!r} now): set MUJOCO_GL=egl (headless, needs libEGL) or "
                          "MUJOCO_GL=osmesa before importing mujoco or jarena") from None


def _film(arena: Arena, physics: PyTree, arenas: Sequence[int], num_states: int, path: Path, options: VideoOptions,
          params: ArenaParams | None, params_axis: int | None) -> tuple[int, float]:
    """Renders states ``0 .. num_states - 1`` of ``arenas`` (tiled if several) and writes ``path``."""
    stride, fps = playback(arena, options.fps)
    frames = render_trajectory(arena, physics, list(arenas), params=params, params_axis=params_axis,
                               width=options.width, height=options.height, camera=options.camera, stride=stride,
                               num_states=num_states, columns=options.columns)
    write_video(path, frames, fps)
    return int(frames.shape[0]), fps


def write_episodes(arena: Arena, physics: PyTree, lengths: Sequence[int], paths: Sequence[str | Path],
                   options: VideoOptions | None = None, *, params: ArenaParams | None = None,
                   params_axis: int | None = None) -> list[Path]:
    """Writes one video per filmed episode.

    Args:
      arena: the arena the episodes ran in.
      physics: physics states (T + 1, K, ...) of K episodes, the reset state first (on device or host).
      lengths: (K,) episode lengths in agent steps; video k shows states ``0 .. lengths[k]``.
      paths: K paths; one without a suffix gets ``options.format``'s (mp4 by default).
      options: frame size, camera, fps.
      params, params_axis: the episodes' arena params, shared or per episode (axis 0).

    Returns:
      The paths written.
    """
    options = options or VideoOptions()
    if len(lengths) != len(paths):
        raise ValueError(f"got {len(lengths)} episode lengths but {len(paths)} video paths")
    written = []
    for k, (length, path) in enumerate(zip(lengths, paths, strict=True)):
        path = _resolve(path, options)
        _film(arena, physics, [k], int(length) + 1, path, options, params, params_axis)
        written.append(path)
    return written


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
      agent, arena: what to film; the arena must render (:func:`jarena.render.can_render`).
      path: the video file, ``.mp4`` or ``.gif`` (a path without a suffix gets ``format``'s).
      episode: an episode id or a sequence of them (``0 .. n - 1`` are the eval split's).
      key: PRNG key of the agent's randomness (default ``jax.random.key(0)``).
      agent_state: the agent's state for a batch of ``len(episodes)`` arenas (default ``agent.init``).
      params, params_axis: arena params, shared or per episode (axis 0).
      width, height, camera: frame size in pixels per episode, and the camera (MuJoCo arenas).
      max_steps: step cap (default: the arena's ``max_episode_steps``).
      fps: playback rate (default: real time).
      columns: grid columns for several episodes (default ``ceil(sqrt(n))``).
      format: ``mp4`` or ``gif`` when ``path`` has no suffix.

    Returns:
      A :class:`Recording` with the path written, frame count, fps and the episodes' results.
    """
    options = VideoOptions(width=width, height=height, camera=camera, fps=fps, format=format, columns=columns)
    path = _resolve(path, options)
    check_video(arena, options, params, params_axis)
    ids = np.atleast_1d(np.asarray(episode, np.int64)).reshape(-1)
    result, physics = run_episodes(agent, arena, key, agent_state=agent_state, params=params,
                                   params_axis=params_axis, episodes=ids, max_steps=max_steps, filmed=int(ids.size))
    frames, fps = _film(arena, physics, range(ids.size), int(result.lengths.max()) + 1, path, options, params,
                        params_axis)
    return Recording(path=path, frames=frames, fps=fps, result=result)
