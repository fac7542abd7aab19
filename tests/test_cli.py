import json

from jarena.cli import main


def test_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "classic|domain:cartpole,task:balance" in out and "oracle_cartpole" in out


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
                 "--set", "rollout_length=64", "--run-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "trained 8192 steps" in out and "| return" in out
    assert (tmp_path / "learning_curve.png").is_file()
    trained = out[out.index("| return"):].split("\n")[0]
    assert main(["evaluate", "ppo", "classic|domain:cartpole", "--checkpoint", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "restored checkpoint" in out and trained in out  # the run's config and policy, same eval episodes
    assert main(["evaluate", "ppo", "classic|domain:cartpole", "--checkpoint", str(tmp_path / "nothing")]) == 2
    assert "no checkpoint found" in capsys.readouterr().err
