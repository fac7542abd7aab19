"""Rendering and videos of episodes.

Physics states are collected on device by the compiled runners; frames are drawn on the host afterwards
by the arena's ``Dynamics.render`` (MuJoCo's renderer for MJX arenas, numpy drawings for the classic
ones), for selected arenas only, and written as MP4 or GIF.

    jarena.record_video(agent, arena, "episode.mp4", episode=0)          # one episode (a runner)
    jarena.record_video(agent, arena, "grid.gif", episode=[0, 1, 2, 3])  # four episodes in a 2 x 2 grid

``jarena.run(..., video=path)``, ``jarena.evaluate(..., videos=N, video_dir=...)`` and
``jarena render AGENT ARENA --out PATH`` film episodes too. Runners sit above this package: it draws
states and writes files, and never runs an agent.
"""

from jarena.render.frames import (
    RenderError,
    can_render,
    render_batch,
    render_trajectory,
    renderer,
    rendering_arenas,
    tile,
)
from jarena.render.record import check_video, write_episodes
from jarena.render.video import FORMATS, VideoOptions, control_timestep, playback, write_video

__all__ = [
    "FORMATS", "RenderError", "VideoOptions", "can_render", "check_video", "control_timestep", "playback",
    "render_batch", "render_trajectory", "renderer", "rendering_arenas", "tile", "write_episodes", "write_video",
]
