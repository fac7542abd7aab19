"""Videos of episodes end to end: record_video, run(video=), evaluate(videos=), train_and_evaluate."""

import dataclasses

import imageio.v2 as imageio
import imageio.v3 as iio
import jax
import numpy as np
import pytest

import jarena
import jarena.render.frames
import jarena_agents
from jarena.render import RenderError, VideoOptions, render_batch
from jarena.runners import record_video


def read(path):
    """A video's frames; a GIF's frames repeated by their delays (Pillow merges identical consecutive frames)."""
    if str(path).endswith(".gif"):
        frames = iio.imread(path, index=None)[..., :3]
        delays = np.array([iio.immeta(path, index=i)["duration"] for i in range(len(frames))])
        return np.repeat(frames, delays // delays.min(), axis=0)
    reader = imageio.get_reader(path, format="FFMPEG")
    try:
        return np.stack(list(reader.iter_data()))
    finally:
        reader.close()


def changed(a, b):
    return float(np.mean(np.any(a != b, axis=-1)))


pytestmark = pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # imageio's ffmpeg reader: fork + exec


@pytest.fixture(scope="module")
def random_agent():
    return jarena_agents.build_agent("random")


def test_record_video_classic_mp4(random_agent, tmp_path):
    arena = jarena.build_arena("classic|domain:pendulum")
    rec = record_video(random_agent, arena, tmp_path / "pendulum.mp4", episode=3, max_steps=30)
    assert rec.path == tmp_path / "pendulum.mp4" and rec.fps == pytest.approx(20) and rec.frames == 31
    assert list(rec.result.episodes) == [3] and list(rec.result.lengths) == [30]
    frames = read(rec.path)
    assert frames.shape == (31, 240, 320, 3)
    assert all(changed(a, b) > 0.001 for a, b in zip(frames[:-1], frames[1:], strict=True))  # the rod moves


def test_record_video_grid_gif_matches_the_episodes(random_agent, tmp_path):
    arena = jarena.build_arena("classic|domain:cartpole")
    rec = record_video(random_agent, arena, tmp_path / "grid", episode=[0, 1, 2], width=80, height=60, format="gif",
                       key=jax.random.key(1))
    lengths = rec.result.lengths
    assert rec.path.suffix == ".gif" and rec.frames == lengths.max() + 1 and lengths.min() < lengths.max()
    np.testing.assert_array_equal(rec.result.returns, lengths)  # cartpole: reward 1 per step
    frames = read(rec.path)
    assert frames.shape == (lengths.max() + 1, 2 * 60 + 2, 2 * 80 + 2, 3)
    cells = [frames[:, :60, :80], frames[:, :60, 82:], frames[:, 62:, :80]]
    start, _ = jarena.batch_reset(arena, None, 3, episodes=np.array([0, 1, 2]))
    first = render_batch(arena, start, width=80, height=60)
    for k, cell in enumerate(cells):
        np.testing.assert_array_equal(cell[0], first[k])  # GIF is lossless for these few colours
        assert changed(cell[0], cell[lengths[k]]) > 0.001  # the episode moved ...
        assert all((cell[lengths[k]:] == cell[lengths[k]]).all(axis=(1, 2, 3)))  # ... and froze once it ended
    assert not frames[:, 62:, 82:].any()  # the fourth cell is empty


def test_record_video_dmc_cartpole(random_agent, tmp_path):
    """The one MJX rollout of the suite (short): physics kept on device, frames rendered after."""
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup")
    rec = record_video(random_agent, arena, tmp_path / "dmc.mp4", episode=0, max_steps=40, width=96, height=72)
    assert rec.fps == pytest.approx(50) and rec.frames == 21  # 100 steps/s: every 2nd of states 0 .. 40
    frames = read(rec.path)
    assert frames.shape == (21, 72, 96, 3)
    assert all(f.std() > 10 for f in frames)  # lit scenes, not blank
    assert changed(frames[0], frames[-1]) > 0.005  # the cart and pole moved


def test_run_with_video_keeps_the_trajectory(random_agent, tmp_path):
    arena = jarena.build_arena("classic|domain:pendulum")
    key = jax.random.key(4)
    plain = jarena.run(random_agent, arena, key, episode=5, max_steps=25)
    filmed = jarena.run(random_agent, arena, key, episode=5, max_steps=25, video=tmp_path / "run.gif",
                        video_options=VideoOptions(width=64, height=64))
    for a, b in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(filmed), strict=True):
        np.testing.assert_array_equal(a, b)
    frames = read(tmp_path / "run.gif")
    assert frames.shape == (26, 64, 64, 3)
    start, _ = arena.reset(None, episode=5)  # an episode's start is a function of its id
    np.testing.assert_array_equal(frames[0], arena.dynamics.render(start.physics, arena.default_params().dynamics,
                                                                   width=64, height=64))


def test_evaluate_with_videos_gives_the_same_results(random_agent, tmp_path):
    arena = jarena.build_arena("classic|domain:cartpole")
    ids = [0, 1, 2, 3, 4]
    plain = jarena.evaluate(random_agent, arena, jax.random.key(2), episodes=ids)
    filmed = jarena.evaluate(random_agent, arena, jax.random.key(2), episodes=ids, videos=2, video_dir=tmp_path,
                             video_options=VideoOptions(width=64, height=48, format="gif"))
    np.testing.assert_array_equal(plain.returns, filmed.returns)
    np.testing.assert_array_equal(plain.lengths, filmed.lengths)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval_episode_0.gif", "eval_episode_1.gif"]
    for i in range(2):
        assert read(tmp_path / f"eval_episode_{i}.gif").shape == (filmed.lengths[i] + 1, 48, 64, 3)
    with pytest.raises(ValueError, match="needs a video_dir"):
        jarena.evaluate(random_agent, arena, episodes=ids, videos=1)
    with pytest.raises(ValueError, match="cannot film 6 of 5 episodes"):
        jarena.evaluate(random_agent, arena, episodes=ids, videos=6, video_dir=tmp_path)


def test_arenas_that_cannot_render_fail_before_running(random_agent, tmp_path):
    arena = jarena.build_arena("classic|domain:pendulum")
    blind = dataclasses.replace(arena, dynamics=dataclasses.replace(arena.dynamics, render=None), name="blind",
                                build_string=None)
    for film in (lambda: record_video(random_agent, blind, tmp_path / "x.mp4"),
                 lambda: jarena.run(random_agent, blind, jax.random.key(0), video=tmp_path / "x.mp4"),
                 lambda: jarena.evaluate(random_agent, blind, videos=1, video_dir=tmp_path)):
        with pytest.raises(RenderError, match=r"arena 'blind' cannot render.*Arenas that render: .*classic\|domain"):
            film()
    assert not any(tmp_path.iterdir())


def test_train_and_evaluate_films_eval_episodes(tmp_path, monkeypatch):
    arena = jarena.build_arena("classic|domain:cartpole")
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "rollout_length": 16, "minibatches": 2,
                                              "total_steps": 2 * 4 * 16})
    result = jarena.train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False,
                                       run_dir=tmp_path / "run", eval_videos=2)
    videos = sorted((tmp_path / "run" / "videos").iterdir())
    assert [p.name for p in videos] == ["eval_episode_0.mp4", "eval_episode_1.mp4"]
    for i, path in enumerate(videos):
        assert read(path).shape == (result.evaluation.lengths[i] + 1, 240, 320, 3)
    # an arena without renderer: no videos and no error (the same arena, seen as one that cannot render,
    # reuses the compiled training)
    monkeypatch.setattr(jarena.training, "can_render", lambda arena: False)
    again = jarena.train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False,
                                      run_dir=tmp_path / "blind")
    np.testing.assert_array_equal(again.evaluation.returns, result.evaluation.returns)  # filming changes nothing
    assert (tmp_path / "blind" / "evaluation.json").is_file() and not (tmp_path / "blind" / "videos").exists()
