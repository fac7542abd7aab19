import json

import pytest

from jarena.cli import main


def test_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "classic|domain:cartpole,task:balance" in out and "oracle_cartpole" in out
    agents = out[out.index("Agents"):].splitlines()[1:]
    assert len({line.index("[") for line in agents if line.strip()}) == 1  # one tag column, longest names too


def test_evaluate_prints_table_and_writes_json(capsys, tmp_path):
    path = tmp_path / "r.json"
    assert main(["evaluate", "oracle_cartpole", "classic|domain:cartpole,task:balance", "--episodes", "4",
                 "--json", str(path)]) == 0
    out = capsys.readouterr().out
    assert "500.00" in out and "100.0%" in out
    data = json.loads(path.read_text())
    assert len(data["episodes"]) == 4 and data["summary"]["success_rate"] == 1.0


def test_errors_are_reported_not_raised(capsys):
    assert main(["evaluate", "random", "classic|domain:nosuch"]) == 2
    assert "unknown classic domain 'nosuch'" in capsys.readouterr().err
    assert main(["evaluate", "oracle_cartpole", "classic|domain:cartpole", "--set", "bad=1"]) == 2
    assert "unknown config key" in capsys.readouterr().err


def test_train_prints_progress_and_table(capsys, tmp_path):
    assert main(["train", "ppo", "classic|domain:cartpole", "--steps", "8192", "--no-progress",
                 "--set", "rollout_length=64", "--run-dir", str(tmp_path), "--validations", "3"]) == 0
    out = capsys.readouterr().out
    assert "trained 8192 steps" in out and "| return" in out
    assert (tmp_path / "learning_curve.png").is_file()
    validations = (tmp_path / "validation.csv").read_text().splitlines()
    assert len(validations) == 1 + 3  # header and 3 validations (16 chunks: after 6, 12 and 16)
    trained = out[out.index("| return"):].split("\n")[0]
    assert main(["evaluate", "ppo", "classic|domain:cartpole", "--checkpoint", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    # the run's config and policy, same eval episodes
    assert "restored the best validated policy" in out and trained in out
    assert main(["evaluate", "ppo", "classic|domain:cartpole", "--checkpoint", str(tmp_path / "nothing")]) == 2
    assert "no checkpoint found" in capsys.readouterr().err


def test_train_names_bad_device_and_launch_flags(capsys, monkeypatch):
    for var in ("JARENA_COORDINATOR", "JARENA_NUM_PROCESSES", "JARENA_PROCESS_ID"):
        monkeypatch.delenv(var, raising=False)
    assert main(["train", "ppo", "classic|domain:cartpole", "--steps", "64", "--coordinator", "localhost:1234"]) == 2
    assert "missing --num-processes, --process-id" in capsys.readouterr().err
    assert main(["train", "ppo", "classic|domain:cartpole", "--steps", "64", "--coordinator", "localhost",
                 "--num-processes", "2", "--process-id", "0"]) == 2
    assert "HOST:PORT" in capsys.readouterr().err
    assert main(["train", "ppo", "classic|domain:cartpole", "--steps", "64", "--validations", "-1"]) == 2
    assert "--validations must be 0 (none) or more" in capsys.readouterr().err
    assert main(["train", "ppo", "classic|domain:cartpole", "--steps", "64", "--devices", "many"]) == 2
    assert "'all' or a positive integer" in capsys.readouterr().err
    assert main(["evaluate", "random", "classic|domain:cartpole", "--episodes", "2", "--devices", "all"]) == 0
    assert "on 1 cpu device(s)" in capsys.readouterr().out
    assert main(["evaluate", "random", "classic|domain:cartpole", "--devices", "3"]) == 2
    assert "choose 'all' or a count from 1 to 1" in capsys.readouterr().err


def test_train_help_explains_devices_and_processes(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    for flag in ("--devices", "--coordinator", "--num-processes", "--process-id", "JARENA_COORDINATOR"):
        assert flag in out


def test_help_shows_defaults_that_say_something(capsys):
    """Every command's --help gives an option's default where it has one (0, 10, best) and never "(default:
    None)" or "(default: False)" (an unset option, an off switch), nor a default its own text already states."""
    for command in ("train", "evaluate", "collect", "render"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        assert "(default: None)" not in out and "(default: False)" not in out, command
        assert "default: real time) (default:" not in out and "total_steps) (default:" not in out  # stated twice
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "seed of the whole run (default: 0)" in out and "(default: 10)" in out


PENDULUM = "classic|domain:pendulum,task:swingup"


def test_collect_then_train_and_evaluate_bc(capsys, tmp_path):
    import re

    import numpy as np

    from jarena.data import TrajectoryDataset

    out_dir = str(tmp_path / "demos")
    assert main(["collect", "oracle_pendulum", PENDULUM, "--out", out_dir, "--trajectories", "4", "--batch", "2",
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "stored 4 trajectories (800 transitions)" in out and f"--set dataset={out_dir}" in out
    printed = float(re.search(r"return (-?[\d.]+) \+-", out).group(1))
    first = [float(t["reward"].sum()) for t in TrajectoryDataset(out_dir)]
    assert printed == pytest.approx(np.mean(first), abs=0.01)

    assert main(["collect", "oracle_pendulum", PENDULUM, "--out", out_dir, "--trajectories", "2"]) == 2
    assert "already holds a dataset (4 trajectories); pass --append" in capsys.readouterr().err
    assert main(["collect", "oracle_pendulum", PENDULUM, "--out", out_dir, "--trajectories", "2", "--append",
                 "--no-progress"]) == 0
    assert "dataset " + out_dir + ": 6 trajectories, 1200 transitions" in capsys.readouterr().out
    dataset = TrajectoryDataset(out_dir)
    added = dataset.get_trajectory(4)["observation"]["state"][0]
    assert not any(np.allclose(added, t["observation"]["state"][0]) for t in list(dataset)[:4])  # new episodes

    run = str(tmp_path / "run")
    assert main(["train", "bc", PENDULUM, "--set", f"dataset={out_dir}", "--set", "hidden=[16]", "--steps", "40",
                 "--no-progress", "--run-dir", run]) == 0
    out = capsys.readouterr().out
    assert "for 40 gradient updates" in out and "| return" in out
    trained = out[out.index("| return"):].split("\n")[0]
    assert main(["evaluate", "bc", PENDULUM, "--checkpoint", run]) == 0
    out = capsys.readouterr().out
    assert "restored the best validated policy" in out and trained in out


def test_collect_and_bc_errors_are_reported(capsys, tmp_path):
    out_dir = str(tmp_path / "demos")
    assert main(["collect", "random", PENDULUM, "--out", out_dir, "--trajectories", "0"]) == 2
    assert "--trajectories must be at least 1" in capsys.readouterr().err
    assert main(["collect", "random", PENDULUM, "--out", out_dir, "--trajectories", "1", "--append",
                 "--overwrite"]) == 2
    assert "exclude each other" in capsys.readouterr().err
    assert main(["collect", "random", PENDULUM, "--out", out_dir, "--trajectories", "1", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["collect", "random", "classic|domain:cartpole", "--out", out_dir, "--trajectories", "1",
                 "--append"]) == 2
    assert "config mismatch on append" in capsys.readouterr().err
    assert main(["train", "bc", PENDULUM, "--steps", "10", "--no-progress"]) == 2
    assert "bc needs demonstrations: set its config key dataset=PATH" in capsys.readouterr().err


def test_collect_help_names_every_option(capsys):
    with pytest.raises(SystemExit):
        main(["collect", "--help"])
    out = capsys.readouterr().out
    for option in ["--out", "--trajectories", "--seed", "--config", "--set", "--batch", "--append", "--overwrite",
                   "--devices"]:
        assert option in out
    assert "jarena train bc" in out


def test_planners_plan_in_the_arena_they_are_evaluated_on(capsys):
    """No tuned config for point_mass: the planner runs on its defaults and models the evaluated arena."""
    assert main(["evaluate", "mppi", "classic|domain:point_mass,time_limit:40", "--episodes", "2",
                 "--set", "samples=16", "--set", "horizon=5"]) == 0
    out = capsys.readouterr().out
    assert "point_mass" in out and "success rate" in out


def test_checkpoints_restore_on_the_arena_they_trained_on(tmp_path):
    """A run's checkpoint holds its arenas' batch state, so it is restored against the arena named in the
    run's config.json; evaluating on another arena with the same specs is allowed, other specs are not."""
    import json

    import jarena
    from jarena.training import trained_arena

    evaluated = jarena.build_arena("classic|domain:cartpole")
    shorter = "classic|domain:cartpole,time_limit:50"
    (tmp_path / "config.json").write_text(json.dumps({"agent": "ppo", "arena": shorter}))
    trained_on = trained_arena(tmp_path, evaluated)
    assert trained_on.build_string == "classic|domain:cartpole,time_limit:50" and trained_on is not evaluated
    (tmp_path / "config.json").write_text(json.dumps({"agent": "ppo", "arena": "classic|domain:cartpole"}))
    assert trained_arena(tmp_path, evaluated) is evaluated
    (tmp_path / "config.json").write_text(json.dumps({"agent": "ppo", "arena": "classic|domain:pendulum"}))
    with pytest.raises(ValueError, match="observation and action specs differ"):
        trained_arena(tmp_path, evaluated)


def test_train_without_a_tuned_config_uses_the_agents_defaults(capsys, tmp_path):
    arena = "classic|domain:point_mass"  # no configs/ppo/ for it
    assert main(["train", "ppo", arena, "--steps", "512", "--no-progress", "--set", "rollout_length=64"]) == 0
    captured = capsys.readouterr()
    assert "no config 'default' for agent 'ppo'" in captured.err and "built-in defaults" in captured.err
    assert "trained 512 steps" in captured.out
    assert main(["train", "ppo", arena, "--config", "tuned", "--steps", "512"]) == 2  # a named config must exist
    assert "no config 'tuned'" in capsys.readouterr().err


COLLECT_ON_TWO_DEVICES = """
import sys
import numpy as np
from jarena.cli import main
from jarena.data import TrajectoryDataset
out = {}
for devices in ("1", "2"):
    path = sys.argv[1] + "/d" + devices
    assert main(["collect", "random", "classic|domain:pendulum", "--out", path, "--trajectories", "3", "--batch", "4",
                 "--devices", devices, "--no-progress"]) == 0
    out[devices] = [(t["episode"], t["reward"]) for t in TrajectoryDataset(path)]
assert [e for e, _ in out["1"]] == [e for e, _ in out["2"]], out
for (_, a), (_, b) in zip(out["1"], out["2"]):
    np.testing.assert_allclose(a, b, rtol=1e-5)
print("SAME", len(out["2"]))
"""


def test_collect_splits_its_arenas_over_devices_and_stores_the_same_trajectories(tmp_path):
    import os
    import subprocess
    import sys

    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2 --xla_cpu_multi_thread_eigen=false",
               JAX_PLATFORMS="cpu")
    done = subprocess.run([sys.executable, "-c", COLLECT_ON_TWO_DEVICES, str(tmp_path)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "SAME 3" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]
    assert "on 2 cpu device(s)" in done.stdout
