"""``jarena render``: film an agent on an arena from the command line."""

import dataclasses

import imageio.v3 as iio

import jarena
from jarena.cli import main


def test_render_writes_a_gif_grid(capsys, tmp_path):
    out = tmp_path / "pendulum"
    assert main(["render", "random", "classic|domain:pendulum", "--out", str(out), "--format", "gif", "--episode",
                 "0", "1", "--max-steps", "15", "--width", "80", "--height", "60", "--seed", "3"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out}.gif: 16 frames at 20 fps" in printed and "episode return(s)" in printed
    frames = iio.imread(f"{out}.gif", index=None)
    assert frames.shape[1:3] == (60, 2 * 80 + 2) and 1 < frames.shape[0] <= 16  # Pillow merges equal frames


def test_render_errors_are_reported(capsys, tmp_path, monkeypatch):
    assert main(["render", "random", "classic|domain:pendulum", "--out", str(tmp_path / "x.avi")]) == 2
    assert "unknown video format 'avi'; valid formats are ['mp4', 'gif']" in capsys.readouterr().err
    assert main(["render", "random", "classic|domain:pendulum", "--out", str(tmp_path / "x.mp4"), "--camera",
                 "top"]) == 2
    assert "cannot render a 320 x 240 frame from camera 'top'" in capsys.readouterr().err  # before the rollout
    arena = jarena.build_arena("classic|domain:pendulum")
    blind = dataclasses.replace(arena, dynamics=dataclasses.replace(arena.dynamics, render=None),
                                build_string="blind|domain:pendulum")
    monkeypatch.setattr(jarena, "build_arena", lambda string: blind)
    assert main(["render", "random", "blind|domain:pendulum", "--out", str(tmp_path / "x.mp4")]) == 2
    err = capsys.readouterr().err
    assert "arena 'blind|domain:pendulum' cannot render" in err and "Arenas that render: classic|domain:" in err
    assert not any(tmp_path.iterdir())
