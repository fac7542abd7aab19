"""Writing frames as MP4 (H.264 through imageio-ffmpeg) or GIF (Pillow), and the frame rate of an arena.

Videos play in real time: one frame per control step of ``arena.dynamics.timestep * arena.tool.substeps``
seconds. Arenas faster than ``max_fps`` (50) are shown every ``stride``-th step; those slower than
``min_fps`` (10) play faster than real time (mountain_car's step is one abstract time unit, acrobot's
0.2 s), so that no video crawls.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np

from jarena.core.arena import Arena

FORMATS = ("mp4", "gif")
MAX_FPS = 50.0  # GIF frame delays are whole centiseconds; viewers slow down delays under 2 cs
MIN_FPS = 10.0


@dataclasses.dataclass(frozen=True)
class VideoOptions:
    """How to film episodes: frame size in pixels, camera (``-1``: MuJoCo's free camera, or a camera's
    name or id), ``fps`` (``None``: real time, see :func:`playback`), file ``format`` for paths without a
    suffix (``None``: mp4; a path's suffix wins) and grid ``columns`` for several episodes in one video."""

    width: int = 320
    height: int = 240
    camera: int | str = -1
    fps: float | None = None
    format: str | None = None
    columns: int | None = None

    def __post_init__(self):
        if int(self.width) < 1 or int(self.height) < 1:
            raise ValueError(f"video width and height must be positive, got {self.width} x {self.height}")
        if self.format is not None:
            check_format(self.format)
        if self.fps is not None and not self.fps > 0:
            raise ValueError(f"video fps must be positive, got {self.fps!r}")


def check_format(format: str) -> str:
    if format not in FORMATS:
        raise ValueError(f"unknown video format {format!r}; valid formats are {list(FORMATS)}")
    return format


def control_timestep(arena: Arena) -> float:
    """Seconds of simulated time per agent step."""
    return float(arena.dynamics.timestep) * max(int(arena.tool.substeps), 1)


def playback(arena: Arena, fps: float | None = None, max_fps: float = MAX_FPS, min_fps: float = MIN_FPS
             ) -> tuple[int, float]:
    """``(stride, fps)``: film every ``stride``-th agent step and play the frames at ``fps``.

    Without ``fps``: real time (``1 / control_timestep``), with the stride that keeps it at most
    ``max_fps``, or ``min_fps`` for slower arenas. With ``fps``: every step, played at ``fps``.
    """
    if fps is not None:
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps!r}")
        return 1, float(fps)
    real = 1.0 / control_timestep(arena)
    if real > max_fps:
        stride = math.ceil(real / max_fps)
        return stride, real / stride
    return 1, max(real, min_fps)


def video_path(path: str | Path, format: str | None = None) -> tuple[Path, str]:
    """``(path, format)``: the format from ``format`` or the path's suffix; a missing suffix is added."""
    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    if format is None:
        if not suffix:
            raise ValueError(f"cannot tell the video format of {str(path)!r}: give a path ending in "
                             f"{' or '.join('.' + f for f in FORMATS)}, or a format")
        return path, check_format(suffix)
    check_format(format)
    if not suffix:
        return path.with_suffix("." + format), format
    if suffix != format:
        raise ValueError(f"video path {str(path)!r} does not end in .{format} (format {format!r})")
    return path, format


def write_video(path: str | Path, frames: np.ndarray, fps: float, format: str | None = None) -> Path:
    """Writes uint8 frames (T, H, W, 3) to ``path`` as MP4 or GIF; returns the path written.

    MP4 is H.264 in yuv420p, which needs even sizes: odd heights or widths are padded by repeating the
    last row or column. GIFs loop forever; Pillow merges identical consecutive frames (adding their delays).
    """
    path, format = video_path(path, format)
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] == 0 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be uint8 (T, H, W, 3) with T >= 1, got {frames.dtype} {frames.shape}")
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if format == "mp4":
        import imageio.v2 as imageio

        pad = ((0, 0), (0, frames.shape[1] % 2), (0, frames.shape[2] % 2), (0, 0))
        frames = np.pad(frames, pad, mode="edge")
        with warnings.catch_warnings():  # the ffmpeg subprocess execs right after fork: JAX's warning does not apply
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
            writer = imageio.get_writer(path, format="FFMPEG", mode="I", fps=float(fps), codec="libx264",
                                        pixelformat="yuv420p", macro_block_size=1, ffmpeg_log_level="error")
            try:
                for frame in frames:
                    writer.append_data(frame)
            finally:
                writer.close()
    else:
        import imageio.v3 as iio

        iio.imwrite(path, frames, extension=".gif", duration=1000.0 / fps, loop=0)
    return path
