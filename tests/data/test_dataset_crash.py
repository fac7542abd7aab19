"""Killing a writer (SIGKILL) mid-trajectory loses at most that trajectory; earlier ones stay intact."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from trajectories import check, trajectory

from jarena.data import TrajectoryDataset

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Appends trajectory(k), k = start, start + 1, ... (at most 400 of them), printing each commit. With
# pause_at >= 0 it stops (sleeps) in the middle of writing trajectory `pause_at`, after some of its
# arrays are written: the dataset writes every array through `write_rows`.
WRITER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {tests!r})
    from trajectories import ACT, GOAL, OBS, trajectory
    import jarena.data.dataset as dataset_module
    from jarena.data import TrajectoryDataset
    path, k, pause_at = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    ds = TrajectoryDataset(path, "a", obs_config=OBS, act_config=ACT, goal_config=GOAL, chunk_bytes=256)
    write_rows, writes = dataset_module.write_rows, [0]
    def paused(array, start, data):
        write_rows(array, start, data)
        if k == pause_at:
            writes[0] += 1
            if writes[0] == 4:
                print("MID", flush=True)
                time.sleep(600)
    dataset_module.write_rows = paused
    for _ in range(400):
        ds.add_trajectory(**trajectory(k))
        print("COMMITTED", k, flush=True)
        k += 1
""").format(tests=os.path.dirname(os.path.abspath(__file__)))


def _writer(path, start, pause_at):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""), JAX_PLATFORMS="cpu")
    return subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(start), str(pause_at)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _kill_after(proc, line_test):
    """Reads the writer's lines until ``line_test(line)``, then kills it; returns the last committed index."""
    last = None
    try:
        for line in proc.stdout:
            if line.startswith("COMMITTED"):
                last = int(line.split()[1])
            if line_test(line):
                break
        else:
            pytest.fail("the writer stopped before it was killed: " + proc.stderr.read()[-2000:])
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    # Commits printed before the kill but not yet read (the writer may run ahead of this reader).
    for line in proc.stdout:
        if line.startswith("COMMITTED"):
            last = int(line.split()[1])
    return last


def _check_intact(path, at_least, at_most):
    with TrajectoryDataset(path, "a") as ds:
        n = ds.num_trajectories()
        assert at_least <= n <= at_most, (n, at_least, at_most)
        for k in range(n):
            check(ds, k)
        assert not [f for _, _, files in os.walk(path) for f in files if f.endswith(".partial")]
        return n, ds


def test_killing_the_writer_mid_trajectory_loses_only_that_trajectory(tmp_path):
    path = tmp_path / "crash"
    # 1. Killed deterministically while trajectory 5 is half written (chunks shared with 0-4 rewritten).
    last = _kill_after(_writer(path, 0, pause_at=5), lambda line: line.startswith("MID"))
    assert last == 4
    n, _ = _check_intact(path, 5, 5)
    # 2. Resume: append from where it stopped, then kill at an arbitrary moment.
    proc = _writer(path, n, pause_at=-1)
    deadline = [None]

    def some_time_after_a_few_commits(line):
        if line.startswith("COMMITTED") and int(line.split()[1]) >= n + 3 and deadline[0] is None:
            deadline[0] = time.monotonic() + 0.05
        return deadline[0] is not None and time.monotonic() > deadline[0]

    last = _kill_after(proc, some_time_after_a_few_commits)
    n, _ = _check_intact(path, last + 1, last + 2)  # the kill may land between a commit and its print
    # 3. And append again after that.
    with TrajectoryDataset(path, "a") as ds:
        ds.add_trajectory(**trajectory(n))
    assert _check_intact(path, n + 1, n + 1)[0] == n + 1
