"""Videos of physics states: render the frames of episodes on the host and write MP4 or GIF files.

The runners keep the physics states of filmed episodes on device inside their compiled loops
(:func:`jarena.runners.record_video`, ``evaluate(videos=N)``, ``run(video=...)``); this module draws and
writes them, and checks up front that an arena can render at all.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax

from jarena.core.arena import Arena
from jarena.core.types import ArenaParams
from jarena.render.frames import RenderError, render_trajectory, renderer
from jarena.render.video import VideoOptions, playback, video_path, write_video

PyTree = Any


def resolve_path(path: str | Path, options: VideoOptions) -> Path:
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


def film(arena: Arena, physics: PyTree, arenas: Sequence[int], num_states: int, path: Path, options: VideoOptions,
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
      params: the episodes' arena params, shared or per episode (see ``params_axis``).
      params_axis: ``None`` (params shared) or ``0`` (one per episode).

    Returns:
      The paths written.
    """
    options = options or VideoOptions()
    if len(lengths) != len(paths):
        raise ValueError(f"got {len(lengths)} episode lengths but {len(paths)} video paths")
    written = []
    for k, (length, path) in enumerate(zip(lengths, paths, strict=True)):
        path = resolve_path(path, options)
        film(arena, physics, [k], int(length) + 1, path, options, params, params_axis)
        written.append(path)
    return written
