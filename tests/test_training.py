"""train_and_evaluate: which policy is evaluated, how often it validates, resuming, and results that no
video failure can lose. A scripted "trainer" whose policy balances the pole only after chosen chunks makes
the selection exact and fast (no learning involved)."""

import csv
import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

import jarena
import jarena.training
import jarena_agents
from jarena.cli import main
from jarena.core.agent import Agent
from jarena.training import train_and_evaluate, training_schedule
from jarena_agents.trainable import TrainableAgent

CARTPOLE = "classic|domain:cartpole"
STEPS_PER_UPDATE = 100


@struct.dataclass
class Switch:
    good: jax.Array  # bool: balance the pole (500 per episode) or push left (falls in about 10 steps)


@dataclasses.dataclass(frozen=True)
class Settings:
    total_steps: int = 20 * STEPS_PER_UPDATE
    steps_per_update: int = STEPS_PER_UPDATE


def scripted_trainer(good_after_chunks: tuple[int, ...]) -> TrainableAgent:
    """One update per chunk; the policy after chunk k (1-based) balances iff k is in ``good_after_chunks``."""
    good = jnp.asarray(good_after_chunks, jnp.int32)

    def act(state, info, key, privileged):
        x, x_dot, theta, theta_dot = jnp.moveaxis(info.observation["state"], -1, 0)
        balance = 0.1 * x + 0.3 * x_dot + 2.0 * theta + 0.5 * theta_dot > 0
        return jnp.where(state.good, balance, False).astype(jnp.int32), state

    def train(updates, arena, n):
        return updates + n, {"episodes": jnp.ones((n,)), "episode_return": jnp.zeros((n,))}

    agent = Agent(name="scripted", init=lambda key, spec, n: Switch(jnp.asarray(False)), act=act)
    return TrainableAgent.wrap(agent, init_training=lambda key, arena: jnp.zeros((), jnp.int32), train=train,
                               policy=lambda updates, spec, deterministic=True: Switch(jnp.any(updates == good)),
                               settings=Settings())


def test_the_best_validated_policy_is_evaluated_ties_to_the_latest(cartpole, tmp_path):
    agent = scripted_trainer((4, 6))  # validated after chunks 2, 4, ..., 20: 4 and 6 tie at 500
    result = train_and_evaluate(agent, cartpole, jax.random.key(0), progress=False, run_dir=tmp_path, eval_videos=0)
    assert [v["update"] for v in result.validations] == list(range(2, 21, 2))
    assert result.selected == {"select": "best", "update": 6, "env_steps": 600, "validation_return": 500.0}
    assert result.evaluation.summary()["return_mean"] == 500.0
    assert "best, step 600 (validation return 500.0)" in result.evaluation.table()
    saved = json.loads((tmp_path / "evaluation.json").read_text())
    assert saved["selected"] == result.selected and saved["summary"]["return_mean"] == 500.0


def test_select_last_evaluates_the_final_policy(cartpole):
    result = train_and_evaluate(scripted_trainer((4, 6)), cartpole, jax.random.key(0), progress=False,
                                select="last")
    assert result.selected["select"] == "last" and result.selected["update"] == 20
    assert result.evaluation.summary()["return_mean"] < 50  # the final policy pushes left: the pole falls
    with pytest.raises(ValueError, match="unknown select 'worst'; choose from best .*, last"):
        train_and_evaluate(scripted_trainer(()), cartpole, jax.random.key(0), progress=False, select="worst")


def test_select_best_by_another_validation_column(cartpole, tmp_path):
    """``best:<metric>`` compares that column: every validation ties on ``faulted_episodes`` (0), so the latest
    validated policy (chunk 20, which pushes left) is kept, where ``best`` keeps chunk 6's; a column the validation
    lacks is an error naming the columns."""
    result = train_and_evaluate(scripted_trainer((4, 6)), cartpole, jax.random.key(0), progress=False,
                                select="best:faulted_episodes", run_dir=tmp_path, eval_videos=0)
    assert result.selected == {"select": "best:faulted_episodes", "update": 20, "env_steps": 2000,
                               "validation_return": result.validations[-1]["return_mean"],
                               "validation_faulted_episodes": 0.0}
    assert result.evaluation.summary()["return_mean"] < 50
    assert "best:faulted_episodes, step 2000 (validation return" in result.evaluation.table()
    with pytest.raises(ValueError, match="has no column 'no_such'; its columns: .*return_mean"):
        train_and_evaluate(scripted_trainer(()), cartpole, jax.random.key(0), progress=False,
                           select="best:no_such")


def test_without_validation_the_final_policy_is_evaluated(cartpole):
    result = train_and_evaluate(scripted_trainer((20,)), cartpole, jax.random.key(0), progress=False,
                                validate_every=0)
    assert result.validations == [] and result.selected["select"] == "last (nothing validated)"
    assert result.evaluation.summary()["return_mean"] == 500.0


def test_an_eval_arena_validates_and_evaluates_in_place_of_the_training_arena(cartpole, tmp_path):
    """Train on one arena, report on another of the same specs (as a run on cheaper physics reports the reference
    physics' return): the balancing policy scores the eval arena's 100-step limit, not the training arena's 500."""
    short = jarena.build_arena(CARTPOLE + ",time_limit:100")
    result = train_and_evaluate(scripted_trainer((4, 6)), cartpole, jax.random.key(0), progress=False,
                                run_dir=tmp_path, eval_videos=0, eval_arena=short)
    assert [v["return_mean"] for v in result.validations][1:3] == [100.0, 100.0]
    assert result.selected["update"] == 6 and result.evaluation.summary()["return_mean"] == 100.0
    assert result.evaluation.summary()["episodes"] == short.num_eval_episodes
    saved = json.loads((tmp_path / "config.json").read_text())
    assert saved["eval_arena"] == CARTPOLE + ",time_limit:100"
    assert saved["key"] == [0, 0]  # the run's key, jax.random.key(0), as its raw words
    with pytest.raises(ValueError, match=r"another observation spec .*same domain and task"):
        train_and_evaluate(scripted_trainer(()), cartpole, jax.random.key(0), progress=False,
                           eval_arena=jarena.build_arena("classic|domain:pendulum"))


def test_the_command_line_trains_on_one_arena_and_evaluates_on_another(tmp_path, capsys):
    code = main(["train", "ppo", CARTPOLE, "--eval-arena", CARTPOLE + ",time_limit:50", "--steps", "2048",
                 "--set", "num_arenas=8", "--set", "rollout_length=64", "--validations", "1", "--videos", "0",
                 "--no-progress", "--run-dir", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert "validating and evaluating on 'classic|domain:cartpole,time_limit:50'" in out
    evaluation = json.loads((tmp_path / "evaluation.json").read_text())
    assert max(e["length"] for e in evaluation["episodes"]) <= 50  # the eval arena's episodes, not the 500-step ones


def test_the_cartpole_main_job_validates_at_least_ten_times(cartpole):
    agent = jarena_agents.build_agent("ppo", jarena.retrieve_config("ppo", cartpole))
    num_chunks, _, validate_every = training_schedule(agent.settings, None, None, None, 10)
    validated = [c for c in range(1, num_chunks + 1) if c % validate_every == 0 or c == num_chunks]
    assert len(validated) >= 10 and validated[-1] == num_chunks  # the final policy is a candidate too


def test_a_resumed_run_says_so_and_keeps_the_best_policy(cartpole, tmp_path, capsys):
    agent = scripted_trainer((4,))
    kwargs = dict(progress=False, run_dir=tmp_path, eval_videos=0, checkpoint_every=1)
    assert train_and_evaluate(agent, cartpole, jax.random.key(0), stop_after_chunks=7, **kwargs).evaluation is None
    assert "resuming" not in capsys.readouterr().out
    resumed = train_and_evaluate(agent, cartpole, jax.random.key(0), **kwargs)
    out = capsys.readouterr().out
    assert f"resuming from step 700 of 2000 (checkpoint {tmp_path.absolute() / 'checkpoints' / '7'})" in out
    assert resumed.selected == {"select": "best", "update": 4, "env_steps": 400, "validation_return": 500.0}
    assert resumed.evaluation.summary()["return_mean"] == 500.0


def test_a_stopped_run_leaves_its_curves_on_disk(cartpole, tmp_path):
    """A run killed by a time limit keeps what it measured: train.csv and validation.csv grow chunk by chunk."""
    agent = scripted_trainer((4,))
    kwargs = dict(progress=False, run_dir=tmp_path, eval_videos=0, checkpoint_every=0, validate_every=2)
    assert train_and_evaluate(agent, cartpole, jax.random.key(0), stop_after_chunks=5, **kwargs).evaluation is None
    with open(tmp_path / "train.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["update"]) for r in rows] == [1, 2, 3, 4, 5]
    with open(tmp_path / "validation.csv") as f:
        assert [int(r["update"]) for r in csv.DictReader(f)] == [2, 4]
    assert not list(tmp_path.glob("*.partial")) and not (tmp_path / "evaluation.json").exists()


def test_training_arguments_are_checked(cartpole):
    for kwargs, message in (({"validations": 0}, "validations must be a positive integer"),
                            ({"eval_videos": -1}, "eval_videos must be an integer >= 0"),
                            ({"total_steps": -5}, "total_steps must be a positive integer")):
        with pytest.raises(ValueError, match=message):
            train_and_evaluate(scripted_trainer(()), cartpole, jax.random.key(0), progress=False, **kwargs)


def test_a_failing_video_encoder_loses_no_result(cartpole, tmp_path, monkeypatch):
    """The encoder (or renderer) fails after evaluating: the results are on disk, the videos are a warning
    that names the fix, and the command still succeeds."""
    import jarena.training

    def no_encoder(*args, **kwargs):
        raise RuntimeError("No ffmpeg exe could be found")

    monkeypatch.setattr(jarena.training, "write_episodes", no_encoder)
    with pytest.warns(UserWarning, match=r"videos not written .*No ffmpeg.*pip install imageio-ffmpeg.*MUJOCO_GL=egl"):
        result = train_and_evaluate(scripted_trainer((2,)), cartpole, jax.random.key(0), progress=False,
                                    run_dir=tmp_path / "run", eval_videos=1)
    assert result.evaluation.summary()["return_mean"] == 500.0
    assert json.loads((tmp_path / "run" / "evaluation.json").read_text())["summary"]["return_mean"] == 500.0
    assert (tmp_path / "run" / "learning_curve.png").is_file()


def test_the_command_line_survives_a_failing_encoder_and_films_on_request(tmp_path, monkeypatch, capsys):
    import jarena.render.record

    args = ["train", "ppo", CARTPOLE, "--steps", "2048", "--no-progress", "--set", "rollout_length=64"]
    assert main(args + ["--run-dir", str(tmp_path / "none"), "--videos", "0"]) == 0
    assert not (tmp_path / "none" / "videos").exists()
    assert main(args + ["--run-dir", str(tmp_path / "one"), "--videos", "1"]) == 0
    assert [p.name for p in (tmp_path / "one" / "videos").iterdir()] == ["eval_episode_0.mp4"]
    capsys.readouterr()

    def no_encoder(path, frames, fps, format=None):
        raise RuntimeError("No ffmpeg exe could be found")

    monkeypatch.setattr(jarena.render.record, "write_video", no_encoder)
    with pytest.warns(UserWarning, match="pip install imageio-ffmpeg"):
        assert main(args + ["--run-dir", str(tmp_path / "broken")]) == 0
    assert "| return" in capsys.readouterr().out and (tmp_path / "broken" / "evaluation.json").is_file()
    assert main(["evaluate", "oracle_cartpole", CARTPOLE, "--episodes", "2", "--videos", "2", "--video-dir",
                 str(tmp_path / "ev")]) == 0
    captured = capsys.readouterr()
    assert "| return" in captured.out and "videos not written" in captured.err and "imageio-ffmpeg" in captured.err
    assert main(["train", "ppo", CARTPOLE, "--videos", "-1"]) == 2


def test_progress_bar_shows_running_return_until_an_episode_ends():
    from jarena.training import shown_return

    nan = float("nan")
    assert shown_return({}) == ""  # before the first chunk
    assert shown_return({"episode_return": 412.34, "running_return": 80.0}) == "ret=412.3"
    assert shown_return({"episode_return": nan, "running_return": 81.26}) == "ret so far=81.3"  # none ended yet
    assert shown_return({"episode_return": nan}) == "ret=nan"  # agents without a running return


def test_seeds_train_at_once_each_as_its_own_run(cartpole, tmp_path):
    """train_seeds vmaps the training over seeds: seed s's curve, validations and final evaluation are the run of
    train_and_evaluate with key s (its final policy evaluated); the seeds differ; the run directory holds each."""
    agent = jarena_agents.build_agent("ppo", dict(jarena.retrieve_config("ppo", cartpole), num_arenas=8,
                                                  rollout_length=64))
    result = jarena.training.train_seeds(agent, cartpole, [0, 3], total_steps=4096, validations=2, select="last",
                                         progress=False, run_dir=tmp_path)
    assert len(result.histories) == 2 and len(result.histories[0]) == len(result.histories[1]) >= 2
    for index, seed in enumerate((0, 3)):
        alone = train_and_evaluate(agent, cartpole, jax.random.key(seed), total_steps=4096, progress=False,
                                   validations=2, select="last", eval_videos=0)
        for key in ("episode_return", "value", "entropy"):
            np.testing.assert_allclose([r[key] for r in result.histories[index]], [r[key] for r in alone.history],
                                       rtol=1e-4)
        assert [v["update"] for v in result.validations[index]] == [v["update"] for v in alone.validations]
        assert len(alone.validations) == 2
        np.testing.assert_allclose([v["return_mean"] for v in result.validations[index]],
                                   [v["return_mean"] for v in alone.validations], rtol=1e-3)
        assert result.evaluations[index].summary()["return_mean"] == pytest.approx(
            alone.evaluation.summary()["return_mean"], rel=1e-3)
    assert result.histories[0][0]["episode_return"] != result.histories[1][0]["episode_return"]
    summary = result.summary()
    returns = [e.summary()["return_mean"] for e in result.evaluations]
    assert summary["seeds"] == 2 and summary["return_mean_mean"] == pytest.approx(np.mean(returns))
    with open(tmp_path / "seeds.csv") as f:
        assert [float(row["seed"]) for row in csv.DictReader(f)] == [0.0, 3.0]
    for seed in (0, 3):
        for name in ("train.csv", "validation.csv", "learning_curve.png"):
            assert (tmp_path / f"seed_{seed}" / name).is_file()
        saved = json.loads((tmp_path / f"seed_{seed}" / "evaluation.json").read_text())
        assert saved["selected"]["select"] == "last" and len(saved["episodes"]) == cartpole.num_eval_episodes
    assert json.loads((tmp_path / "config.json").read_text())["seeds"] == [0, 3]
    with pytest.raises(ValueError, match="distinct seeds"):
        jarena.training.train_seeds(agent, cartpole, [1, 1], progress=False)
    with pytest.raises(ValueError, match="validations must be a whole number >= 0"):
        jarena.training.train_seeds(agent, cartpole, [1, 2], validations=-1, progress=False)


def test_seeds_keep_each_seeds_best_validated_policy(cartpole, tmp_path):
    """With validations, each seed's policy is chosen as train_and_evaluate chooses: the scripted policy balances
    only after chunks 4 and 6, so best keeps chunk 6's for every seed (500) and last evaluates chunk 20's (the pole
    falls); without validations best falls back to the last, saying so."""
    agent = scripted_trainer((4, 6))
    best = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False, run_dir=tmp_path)
    for evaluation in best.evaluations:
        assert evaluation.selected == {"select": "best", "update": 6, "env_steps": 600, "validation_return": 500.0}
        assert evaluation.summary()["return_mean"] == 500.0
    assert "best, step 600" in best.table()
    saved = json.loads((tmp_path / "seed_1" / "evaluation.json").read_text())
    assert saved["selected"]["update"] == 6
    last = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, select="last", progress=False)
    assert all(e.selected["select"] == "last" and e.summary()["return_mean"] < 50 for e in last.evaluations)
    unvalidated = jarena.training.train_seeds(agent, cartpole, [0, 1], progress=False)
    assert all(e.selected["select"] == "last (nothing validated)" for e in unvalidated.evaluations)
    with pytest.raises(ValueError, match="unknown select 'worst'"):
        jarena.training.train_seeds(agent, cartpole, [0, 1], select="worst", progress=False)


def test_seeds_resume_from_their_checkpoint(cartpole, tmp_path, capsys):
    """A several-seed run stopped after 7 chunks resumes from its checkpoint after chunk 5 (the default: every 5
    chunks): its curves, validations and choice equal an uninterrupted run's, and the policy kept before the stop
    (chunk 4's, then chunk 6's again) is the one evaluated (500; the final policy drops the pole)."""
    agent = scripted_trainer((4, 6))
    whole = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False)
    stopped = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False, run_dir=tmp_path,
                                          stop_after_chunks=7)
    assert stopped.evaluations == [] and [len(h) for h in stopped.histories] == [7, 7]
    assert (tmp_path / "checkpoints" / "5").is_dir()
    resumed = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False, run_dir=tmp_path)
    assert "resuming from step 500 of 2000" in capsys.readouterr().out
    for ours, theirs in ((resumed, whole),):
        for a, b in zip(ours.histories, theirs.histories, strict=True):
            assert [{k: v for k, v in r.items() if k != "seconds"} for r in a] == \
                [{k: v for k, v in r.items() if k != "seconds"} for r in b]
        assert ours.validations == theirs.validations
    assert [e.selected for e in resumed.evaluations] == [e.selected for e in whole.evaluations]
    assert all(e.selected["update"] == 6 and e.summary()["return_mean"] == 500.0 for e in resumed.evaluations)
    # stopped after chunk 7 with a checkpoint after it, the kept policy (chunk 6's) comes back from the checkpoint
    again = tmp_path / "again"
    jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False, run_dir=again,
                                checkpoint_every=7, stop_after_chunks=7)
    finished = jarena.training.train_seeds(agent, cartpole, [0, 1], validations=10, progress=False, run_dir=again,
                                           checkpoint_every=7)
    assert all(e.selected["update"] == 6 and e.summary()["return_mean"] == 500.0 for e in finished.evaluations)
    with open(again / "seed_1" / "validation.csv") as f:
        assert [float(r["update"]) for r in csv.DictReader(f)] == list(range(2, 21, 2))
    # one seed's policy from the run's checkpoint, as `jarena evaluate --checkpoint RUN/seed_<s>` takes it
    best = jarena.training.restore_policy(agent, cartpole, tmp_path / "seed_1")
    assert bool(best.good)  # chunk 6's, kept
    assert not bool(jarena.training.restore_policy(agent, cartpole, tmp_path / "seed_1", select="last").good)
    with pytest.raises(ValueError, match="trained seeds \\[0, 1\\]; give one of"):
        jarena.training.restore_policy(agent, cartpole, tmp_path / "seed_7")
    with pytest.raises(ValueError, match=r"holds a run of seeds \[0, 1\], not of seeds \[0, 2\]"):
        jarena.training.train_seeds(agent, cartpole, [0, 2], progress=False, run_dir=tmp_path)
    with pytest.raises(ValueError, match=r"holds a run of seeds \[0, 1\] \(jarena train --seeds 2\), not of one"):
        train_and_evaluate(agent, cartpole, jax.random.key(0), progress=False, run_dir=tmp_path)
    single = tmp_path / "single"
    train_and_evaluate(agent, cartpole, jax.random.key(0), progress=False, run_dir=single, stop_after_chunks=5,
                       eval_videos=0)
    with pytest.raises(ValueError, match=r"holds a run of one seed \(no --seeds\), not of seeds \[0, 1\]"):
        jarena.training.train_seeds(agent, cartpole, [0, 1], progress=False, run_dir=single)
    with pytest.raises(ValueError, match="checkpoint_every"):
        jarena.training.train_seeds(agent, cartpole, [0, 1], progress=False, checkpoint_every=-1)


def test_the_command_line_trains_several_seeds_at_once(tmp_path, capsys):
    code = main(["train", "ppo", CARTPOLE, "--seeds", "2", "--seed", "5", "--steps", "2048", "--set", "num_arenas=8",
                 "--set", "rollout_length=64", "--no-progress", "--run-dir", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert "seeds 5 to 6, at once" in out and "all 2 |" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoints", "config.json", "seed_5", "seed_6",
                                                          "seeds.csv"]
    for seed in (5, 6):  # validated 10 times, as a single run by default
        with open(tmp_path / f"seed_{seed}" / "validation.csv") as f:
            assert len(list(csv.DictReader(f))) >= 2
    # one seed's evaluated policy, evaluated again from the run's checkpoint: the same episodes' return
    assert main(["evaluate", "ppo", CARTPOLE, "--checkpoint", str(tmp_path / "seed_6"), "--json",
                 str(tmp_path / "again.json")]) == 0
    again = json.loads((tmp_path / "again.json").read_text())["summary"]["return_mean"]
    trained = json.loads((tmp_path / "seed_6" / "evaluation.json").read_text())["summary"]["return_mean"]
    assert again == pytest.approx(trained, rel=1e-6)


def test_a_final_evaluation_line_outside_the_plotted_returns_widens_the_range_to_show_it():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jarena.training import _show_level

    fig, ax = plt.subplots()
    ax.plot([0, 1], [60.0, 95.0])
    low, high = ax.get_ylim()
    _show_level(ax, 96.3)  # above every plotted point: pushed off the frame without the widening
    assert ax.get_ylim()[0] == low and ax.get_ylim()[1] > 96.3 + 1.0
    _show_level(ax, 80.0)  # already inside: unchanged
    assert ax.get_ylim()[1] > 96.3 + 1.0 and ax.get_ylim()[0] == low
    plt.close(fig)
