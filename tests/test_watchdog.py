"""The watchdog of a multi-process run: from the other processes' records it finds a process that went silent,
failed, was terminated, fell behind at a collective point or fetches something else there (unit tests with a
stand-in key-value store), and, on real processes launched as a user launches them, a killed, stopped or
terminated process stops the others within a bounded time and the run resumes from its checkpoints."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from jarena import watchdog
from jarena.watchdog import Limits, Watchdog, _Record


class Store:
    """The coordination service's key-value store, in memory."""

    def __init__(self):
        self.values = {}

    def key_value_set(self, key, value, allow_overwrite=False):
        self.values[key] = value

    def key_value_try_get(self, key):
        if key not in self.values:
            raise RuntimeError(f"NOT_FOUND: {key}")
        return self.values[key]


def _watchdog(limits: Limits | None = None) -> Watchdog:
    return Watchdog(Store(), 0, 3, limits or Limits(heartbeat=60, wait=900), "localhost:1234")


def _see(dog: Watchdog, now: float, **records) -> str | None:
    dog._others.update({int(p[1:]): r for p, r in records.items()})
    return dog._problem(now)


def test_a_silent_process_is_missing_after_the_heartbeat_limit():
    dog = _watchdog()
    assert _see(dog, 0.0, p1=_Record(beat=1), p2=_Record(beat=1)) is None
    assert _see(dog, 50.0, p1=_Record(beat=9), p2=_Record(beat=1)) is None
    problem = _see(dog, 61.0, p1=_Record(beat=10), p2=_Record(beat=1))
    assert problem.startswith("process 2 stopped responding: no heartbeat for 61 s")


def test_a_process_that_fails_or_is_terminated_stops_the_others_at_once():
    dog = _watchdog()
    assert _see(dog, 0.0, p1=_Record(beat=1, state="failed", message="ValueError: bad arena")) == \
        "process 1 stopped: ValueError: bad arena"
    dog = _watchdog()
    assert "process 2 was terminated" in _see(dog, 0.0, p2=_Record(state="terminated", message="SIGTERM"))


def test_a_process_behind_at_a_collective_point_is_given_the_wait_limit():
    dog = _watchdog(Limits(heartbeat=60, wait=100))
    dog.enter("validation 3")
    dog.enter("checkpoint 4")
    dog._entered = 0.0  # it reached point 2 at time 0
    for t in range(0, 100, 10):  # alive (beating), but stuck at point 1
        assert _see(dog, float(t), p1=_Record(beat=t, point=1, name="validation 3"),
                    p2=_Record(beat=t, point=2, name="checkpoint 4")) is None
    problem = _see(dog, 101.0, p1=_Record(beat=101, point=1, name="validation 3"),
                   p2=_Record(beat=101, point=2, name="checkpoint 4"))
    assert problem == ("process 1 has not reached collective point 2 ('checkpoint 4') in 101 s; it is still at "
                       "point 1 ('validation 3')")


def test_the_wait_counts_from_when_this_process_got_ahead():
    # both sat at point 1 for an hour (a long computation); this one moved on to point 2 a minute ago
    dog = _watchdog(Limits(heartbeat=60, wait=100))
    dog.enter("training chunk 1")
    assert _see(dog, 0.0, p1=_Record(beat=0, point=1), p2=_Record(beat=0, point=1)) is None
    dog.enter("training chunk 2")
    dog._entered = 3600.0
    assert _see(dog, 3660.0, p1=_Record(beat=3660, point=1), p2=_Record(beat=3660, point=2)) is None
    assert "process 1 has not reached collective point 2" in _see(dog, 3701.0, p1=_Record(beat=3701, point=1),
                                                                  p2=_Record(beat=3701, point=2))


def test_processes_fetching_different_results_at_one_point_are_stopped_at_once():
    dog = _watchdog()
    dog.enter("eval episodes", "5 arrays, 2000 bytes, #aaaa")
    problem = _see(dog, 0.0, p1=_Record(point=1, name="eval episodes", fingerprint="6 arrays, 9000 bytes, #bbbb"))
    assert "entered collective point 1 ('eval episodes') with different results to fetch" in problem


def test_a_process_that_finished_while_another_waits_ran_another_program():
    dog = _watchdog()
    dog.enter("training chunk 1")
    dog.enter("training chunk 2")
    problem = _see(dog, 0.0, p1=_Record(point=1, name="training chunk 1", state="finished"), p2=_Record(point=2))
    assert problem.startswith("process 1 finished at collective point 1")
    dog = _watchdog()  # finished at the same point: it waits for this process to finish (no problem)
    assert _see(dog, 1e6, p1=_Record(point=0, state="finished"), p2=_Record(beat=1)) is None


def test_limits_are_checked_and_read_from_the_environment(monkeypatch):
    with pytest.raises(ValueError, match="heartbeat must be a positive number of seconds"):
        Limits(heartbeat=0)
    monkeypatch.setenv("JARENA_WAIT_TIMEOUT", "12.5")
    assert Limits.from_environment() == Limits(heartbeat=watchdog.HEARTBEAT_SECONDS, wait=12.5)
    monkeypatch.setenv("JARENA_HEARTBEAT_TIMEOUT", "soon")
    with pytest.raises(ValueError, match="JARENA_HEARTBEAT_TIMEOUT must be a number of seconds, got 'soon'"):
        Limits.from_environment()


# -- real processes: `jarena train` on two processes, launched as a user launches them ---------------------------

def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


class _Launch:
    """``jarena train ppo`` on classic cart-pole in two processes on localhost, with the command's defaults (1,024
    steps per update: 10 chunks of one update, a checkpoint every 5, two eval videos)."""

    def __init__(self, run: Path, env: dict | None = None):
        port = _free_port()
        self.run, self.logs = run, [run.parent / f"{run.name}_{i}.log" for i in range(2)]
        env = dict(os.environ, JAX_PLATFORMS="cpu", **(env or {}))
        command = [sys.executable, "-m", "jarena.cli", "train", "ppo", "classic|domain:cartpole", "--steps", "10240",
                   "--no-progress", "--run-dir", str(run), "--coordinator", f"localhost:{port}",
                   "--num-processes", "2"]
        self.processes = []
        for i, log in enumerate(self.logs):
            with open(log, "w") as f:  # the child keeps its own handle
                self.processes.append(subprocess.Popen(command + ["--process-id", str(i)], env=env, stdout=f,
                                                       stderr=subprocess.STDOUT))

    def wait_for_checkpoint(self, step: int, timeout: float = 300) -> None:
        deadline = time.monotonic() + timeout
        while not (self.run / "checkpoints" / str(step)).is_dir():
            assert time.monotonic() < deadline, self.output(0)[-3000:]
            assert all(p.poll() is None for p in self.processes), self.output(0)[-3000:]
            time.sleep(0.1)

    def wait_for_rows(self, rows: int, timeout: float = 300) -> None:
        """Until process 0's train.csv (rewritten atomically after every chunk) holds ``rows`` chunks."""
        deadline = time.monotonic() + timeout
        path = self.run / "train.csv"
        while not (path.is_file() and len(path.read_text().strip().splitlines()) > rows):
            assert time.monotonic() < deadline, self.output(0)[-3000:]
            assert all(p.poll() is None for p in self.processes), self.output(0)[-3000:]
            time.sleep(0.1)

    def wait(self, timeout: float) -> list[int]:
        try:
            return [p.wait(timeout=timeout) for p in self.processes]
        finally:
            for p in self.processes:
                p.kill()
                p.wait()

    def output(self, i: int) -> str:
        return self.logs[i].read_text()


def test_a_killed_process_stops_the_others_sigterm_ends_all_and_the_run_resumes(tmp_path):
    run = tmp_path / "run"
    first = _Launch(run)
    first.wait_for_checkpoint(5)
    first.processes[1].send_signal(signal.SIGKILL)
    start = time.monotonic()
    codes = first.wait(timeout=120)
    # a collective with the killed process fails at once and the watchdog names it as missing; a process waiting in
    # the checkpoint's own barrier (orbax's, through the coordination service) learns it from the heartbeats that
    # stopped, after JARENA_HEARTBEAT_TIMEOUT (60 s by default)
    assert time.monotonic() - start < watchdog.HEARTBEAT_SECONDS + 15
    assert codes[0] != 0
    stopped = first.output(0)
    assert re.search(r"process 1 (went missing|stopped responding: no heartbeat)", stopped), stopped[-3000:]
    assert f"the run resumes from its last checkpoint in {run / 'checkpoints'}" in stopped

    second = _Launch(run)  # the same command: resumes, then a scheduler's SIGTERM reaches both processes
    second.wait_for_rows(7)
    for p in second.processes:
        p.send_signal(signal.SIGTERM)
    start = time.monotonic()
    assert second.wait(timeout=120) == [143, 143]
    assert time.monotonic() - start < 20
    assert "resuming from step 5120" in second.output(0)
    assert sorted(os.listdir(run / "checkpoints")) == ["5"]
    assert "received SIGTERM" in second.output(0) and "received SIGTERM" in second.output(1)

    third = _Launch(run)  # and once more: it resumes from what the terminated run saved and finishes
    assert third.wait(timeout=600) == [0, 0], third.output(0)[-3000:]
    assert "resuming from step 5120" in third.output(0)
    assert (run / "evaluation.json").is_file() and len(list((run / "videos").glob("eval_episode_*"))) == 2
    with open(run / "train.csv") as f:
        assert len(f.read().strip().splitlines()) == 1 + 10


def test_a_stopped_process_makes_the_other_fail_within_the_heartbeat_limit(tmp_path):
    # SIGSTOP: alive to the operating system, silent to the others (a hung machine); 5 s instead of the default
    # 60 s so the test is short
    launch = _Launch(tmp_path / "run", env={"JARENA_HEARTBEAT_TIMEOUT": "5"})
    try:
        launch.wait_for_checkpoint(5)
        launch.processes[1].send_signal(signal.SIGSTOP)
        start = time.monotonic()
        assert launch.processes[0].wait(timeout=120) == watchdog.EXIT_STATUS
        assert time.monotonic() - start < 30
        assert "process 1 stopped responding: no heartbeat for" in launch.output(0), launch.output(0)[-3000:]
    finally:
        for p in launch.processes:
            p.kill()
            p.wait()
