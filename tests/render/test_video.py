"""Writing MP4 and GIF files and reading them back; the frame rate of arenas."""

import dataclasses

import imageio.v2 as imageio
import imageio.v3 as iio
import numpy as np
import pytest

import jarena
from jarena.render import VideoOptions, control_timestep, playback, write_video

pytestmark = pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # imageio's ffmpeg reader: fork + exec


def moving_square(num_frames, height=48, width=64):
    frames = np.zeros((num_frames, height, width, 3), np.uint8)
    frames[:] = (30, 60, 90)
    for t in range(num_frames):
        frames[t, 10:26, 3 * t: 3 * t + 16] = (250, 200, 20)
    return frames


def read_mp4(path):
    reader = imageio.get_reader(path, format="FFMPEG")
    try:
        return np.stack(list(reader.iter_data())), reader.get_meta_data()["fps"]
    finally:
        reader.close()


def test_mp4_round_trip(tmp_path):
    frames = moving_square(12)
    path = write_video(tmp_path / "square.mp4", frames, fps=25)
    back, fps = read_mp4(path)
    assert back.shape == frames.shape and fps == 25
    assert np.abs(back.astype(int) - frames).mean() < 4  # H.264 is lossy, but close
    bright = [np.argwhere(f[..., 0] > 160)[:, 1].mean() for f in back]  # the square moves right 3 px a frame
    np.testing.assert_allclose(np.diff(bright), 3, atol=0.5)
    odd = write_video(tmp_path / "odd.mp4", moving_square(3, height=47, width=63), fps=10)
    assert read_mp4(odd)[0].shape == (3, 48, 64, 3)  # yuv420p needs even sizes: padded


def test_gif_round_trip(tmp_path):
    frames = moving_square(7)
    path = write_video(tmp_path / "square.gif", frames, fps=20)
    back = iio.imread(path, index=None)
    assert back.shape == frames.shape
    np.testing.assert_array_equal(back[..., :3], frames)  # two colours: exact through the palette
    assert iio.immeta(path, index=0)["duration"] == 50  # milliseconds per frame
    assert write_video(tmp_path / "nosuffix", frames, fps=20, format="gif").name == "nosuffix.gif"


def test_bad_video_arguments(tmp_path):
    frames = moving_square(2)
    with pytest.raises(ValueError, match=r"unknown video format 'avi'; valid formats are \['mp4', 'gif'\]"):
        write_video(tmp_path / "a.avi", frames, fps=10)
    with pytest.raises(ValueError, match="cannot tell the video format"):
        write_video(tmp_path / "a", frames, fps=10)
    with pytest.raises(ValueError, match=r"does not end in \.gif"):
        write_video(tmp_path / "a.mp4", frames, fps=10, format="gif")
    with pytest.raises(ValueError, match=r"frames must be uint8 \(T, H, W, 3\)"):
        write_video(tmp_path / "a.mp4", frames.astype(np.float32), fps=10)
    with pytest.raises(ValueError, match="fps must be positive"):
        write_video(tmp_path / "a.mp4", frames, fps=0)
    with pytest.raises(ValueError, match="unknown video format"):
        VideoOptions(format="webm")


def test_playback_is_real_time_within_limits():
    cartpole = jarena.build_arena("classic|domain:cartpole")  # 0.02 s per step: 50 fps
    assert control_timestep(cartpole) == pytest.approx(0.02) and playback(cartpole) == (1, pytest.approx(50))
    repeated = jarena.build_arena("classic|domain:cartpole,action:repeat(4)")  # 0.08 s per agent step
    assert playback(repeated) == (1, pytest.approx(12.5))
    fast = dataclasses.replace(cartpole, dynamics=dataclasses.replace(cartpole.dynamics, timestep=0.005))
    assert playback(fast) == (4, pytest.approx(50))  # 200 steps per second: every 4th step at 50 fps
    assert playback(jarena.build_arena("classic|domain:acrobot")) == (1, 10)  # 5 fps real time: sped up
    assert playback(cartpole, fps=7) == (1, 7)
