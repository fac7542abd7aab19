"""Data-parallel training on a device mesh (jarena.distributed): several CPU devices in one process and several
processes on localhost (jax.distributed with gloo) compute what one device computes -- training,
evaluation, perform_parallel and collect -- and a stopped multi-process run resumes from its checkpoints."""

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from jarena import distributed

WORKER = Path(__file__).with_name("distributed_worker.py")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _run_all(commands: list[list[str]], env: dict, cwd: Path | None = None) -> list[str]:
    """Starts every command at once (the processes of one run), waits for all, and returns their outputs;
    each must succeed."""
    running = [subprocess.Popen(c, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd)
               for c in commands]
    try:
        outputs = [p.communicate(timeout=600)[0] for p in running]
    finally:
        for p in running:
            p.kill()
    for p, output in zip(running, outputs, strict=True):
        assert p.returncode == 0, output[-4000:]
    return outputs


def _cpu_devices(count: int) -> dict:
    """The environment of a subprocess whose CPU is split into ``count`` JAX devices. XLA's backend (LLVM)
    optimisation is off: these runs are tiny and compare what programs compute, not how fast, and each process
    compiles its programs itself (the processes of a run concurrently, so none finds the others' in the
    persistent cache), which unoptimised takes about half the time."""
    return dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={count} "
                "--xla_cpu_multi_thread_eigen=false --xla_backend_optimization_level=0", JAX_PLATFORMS="cpu")


def _launch(out: Path, agent: str, devices: str, *, cpu_devices: int, processes: int = 1,
            stop_after: int | None = None) -> None:
    """Runs the worker in ``processes`` processes of ``cpu_devices`` CPU devices each and waits for all."""
    env = _cpu_devices(cpu_devices)
    port = _free_port()
    commands = []
    for process in range(processes):
        command = [sys.executable, str(WORKER), str(out), agent, devices]
        if processes > 1:
            command += [f"localhost:{port}", str(processes), str(process)]
        if stop_after is not None:
            command += ["--stop-after", str(stop_after)]
        commands.append(command)
    _run_all(commands, env)


def _result(out: Path, process: int = 0) -> dict:
    with np.load(out / f"result_{process}.npz") as f:
        data = dict(f)
    return {"leaves": [data[f"arr_{i}"] for i in range(sum(k.startswith("arr_") for k in data))],
            "history": json.loads(str(data["history"])), "evaluation": data["evaluation"],
            "devices": int(data["devices"]), "processes": int(data["processes"]),
            "batch_shards": int(data["batch_shards"]), "fixed_returns": data["fixed_policy_returns"],
            "fixed_lengths": data["fixed_policy_lengths"], "rollout_steps": data["rollout_steps"],
            "rollout_shards": int(data["rollout_shards"]), "collected": data["collected"]}


def _assert_same_run(got: dict, want: dict) -> None:
    """The same training run: every leaf of the final train state and the losses of every chunk agree to
    float tolerance (the sharded program sums in another order); the final evaluations agree closely (a
    policy differing in the 7th digit may act differently late in a chaotic episode). One fixed policy
    evaluated on the mesh gives what one device gives: the same episode lengths, returns to float
    tolerance (a smaller batch per device may sum a layer's products in another order). A random agent's
    perform_parallel rollout over all devices steps as on one device, and collect stores the same
    trajectories."""
    assert len(got["leaves"]) == len(want["leaves"])
    for a, b in zip(got["leaves"], want["leaves"], strict=True):
        np.testing.assert_allclose(a, b, rtol=2e-4, atol=2e-5)
    assert len(got["history"]) == len(want["history"])
    for a, b in zip(got["history"], want["history"], strict=True):
        assert a.keys() == b.keys()
        for k in a:
            if k != "seconds":
                np.testing.assert_allclose(a[k], b[k], rtol=2e-4, atol=2e-5, err_msg=k)
    np.testing.assert_allclose(np.mean(got["evaluation"]), np.mean(want["evaluation"]), rtol=0.02)
    np.testing.assert_array_equal(got["fixed_lengths"], want["fixed_lengths"])
    assert got["rollout_shards"] == got["devices"]  # perform_parallel spreads its arenas over all devices
    np.testing.assert_allclose(got["rollout_steps"], want["rollout_steps"], rtol=1e-6, atol=1e-6)
    if len(got["collected"]):  # the writing process: the same trajectories (episode ids and returns) stored
        assert got["collected"].shape == (6, 2)
        np.testing.assert_allclose(got["collected"], want["collected"], rtol=1e-5)
    np.testing.assert_allclose(got["fixed_returns"], want["fixed_returns"], rtol=1e-4)


@pytest.fixture(scope="module")
def one_device(tmp_path_factory):
    """The reference: each agent trained on one device."""
    runs = {}
    for agent in ("ppo", "sac"):
        out = tmp_path_factory.mktemp(f"{agent}_one")
        _launch(out, agent, "1", cpu_devices=1)
        runs[agent] = _result(out)
        assert runs[agent]["devices"] == 1 and runs[agent]["batch_shards"] == 1
    return runs


@pytest.mark.parametrize("agent", ["ppo", "sac"])
def test_four_devices_in_one_process_train_as_one_device(agent, one_device, tmp_path):
    _launch(tmp_path, agent, "all", cpu_devices=4)
    got = _result(tmp_path)
    assert got["devices"] == 4 and got["batch_shards"] == 4  # the arenas really are split four ways
    _assert_same_run(got, one_device[agent])


def test_two_processes_of_four_devices_train_as_one_device_and_a_stopped_run_resumes(one_device, tmp_path):
    # 2 processes x 4 devices (a cluster of two 4-GPU hosts, on CPUs; PPO's 8 arenas leave one
    # arena per device, and its minibatches of 64 samples 8 per device); the first launch stops after one chunk
    # (as a killed job would, after its checkpoint), the second resumes from the checkpoints all processes wrote
    _launch(tmp_path, "ppo", "all", cpu_devices=4, processes=2, stop_after=1)
    assert sorted(os.listdir(tmp_path / "run" / "checkpoints")) == ["1"]
    assert not (tmp_path / "result_0.npz").exists()
    _launch(tmp_path, "ppo", "all", cpu_devices=4, processes=2)
    assert len(_result(tmp_path, 0)["collected"]) == 6 and len(_result(tmp_path, 1)["collected"]) == 0
    for process in (0, 1):
        got = _result(tmp_path, process)
        assert got["processes"] == 2 and got["devices"] == 8 and got["batch_shards"] == 8  # over both processes
        _assert_same_run(got, one_device["ppo"])
    # only process 0 writes the logs: one train.csv, with every chunk of both launches
    with open(tmp_path / "run" / "train.csv") as f:
        assert len(f.read().strip().splitlines()) == 1 + len(one_device["ppo"]["history"])


def test_four_processes_train_as_one_device(one_device, tmp_path):
    _launch(tmp_path, "ppo", "all", cpu_devices=1, processes=4)
    got = _result(tmp_path, 3)
    assert got["processes"] == 4 and got["devices"] == 4
    _assert_same_run(got, one_device["ppo"])


# A wider mesh (on CPUs): 8 devices, the width of one 8-GPU node, in one process (as 2 processes of 4
# devices: the resume test above).
def test_eight_devices_in_one_process_train_as_one_device(one_device, tmp_path):
    _launch(tmp_path, "ppo", "all", cpu_devices=8)
    got = _result(tmp_path)
    assert got["processes"] == 1 and got["devices"] == 8 and got["batch_shards"] == 8
    _assert_same_run(got, one_device["ppo"])


def _cli_on_processes(args: list[str], processes: int, cwd: Path) -> list[str]:
    """``python -m jarena.cli ARGS`` in ``processes`` processes of one CPU device each, launched as a cluster
    launcher would (only the launch flags added), or with one process on a mesh of as many CPU devices (the
    reference); returns their outputs."""
    env = _cpu_devices(1 if processes > 1 else 2)
    command = [sys.executable, "-m", "jarena.cli", *args]
    if processes == 1:
        return _run_all([command + ["--devices", "all"]], env, cwd)
    port = _free_port()
    return _run_all([command + ["--coordinator", f"localhost:{port}", "--num-processes", str(processes),
                                "--process-id", str(i)] for i in range(processes)], env, cwd)


def _csv_rows(path: Path) -> list[dict]:
    import csv

    with open(path) as f:
        return [{k: float(v) for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]


def test_the_command_line_launches_two_processes_with_its_defaults(tmp_path):
    """``jarena train`` with --coordinator/--num-processes/--process-id and the command's defaults (videos
    included), as a cluster launcher would start it: both processes train on the 2-device mesh and finish, only
    process 0 prints the results and writes the run, and the run is the one process's on two devices."""
    args = ["train", "ppo", "classic|domain:cartpole", "--steps", "512", "--set", "num_arenas=8", "--set",
            "rollout_length=32", "--no-progress", "--run-dir", "run"]
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    _cli_on_processes(args, 1, tmp_path / "one")
    outputs = _cli_on_processes(args, 2, tmp_path / "two")
    assert "on 2 cpu devices of 2 processes" in outputs[0] and "| return" in outputs[0]
    assert "| return" not in outputs[1] and "training 'ppo'" not in outputs[1]
    one, two = tmp_path / "one" / "run", tmp_path / "two" / "run"
    assert (two / "checkpoints").is_dir() and (two / "learning_curve.png").is_file()
    assert sorted(p.name for p in (two / "videos").iterdir()) == ["eval_episode_0.mp4", "eval_episode_1.mp4"]
    for name in ("train.csv", "validation.csv"):
        got, want = _csv_rows(two / name), _csv_rows(one / name)
        assert len(got) == len(want) and got[0].keys() == want[0].keys()
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(list(a.values()), list(b.values()), rtol=2e-4, atol=2e-5)
    got, want = (json.loads((run / "evaluation.json").read_text())["summary"] for run in (two, one))
    np.testing.assert_allclose(got["return_mean"], want["return_mean"], rtol=0.02)


def test_evaluate_and_collect_launch_two_processes(tmp_path):
    """``jarena evaluate`` (filming two episodes) and ``jarena collect`` on two processes finish, and give what
    one process gives: the same per-episode results and videos, the same stored trajectories."""
    from jarena.data import TrajectoryDataset

    evaluate = ["evaluate", "oracle_pendulum", "classic|domain:pendulum,task:swingup", "--episodes", "8",
                "--videos", "2", "--json", "eval.json"]
    collect = ["collect", "oracle_pendulum", "classic|domain:pendulum,task:swingup", "--out", "demos",
               "--trajectories", "6", "--no-progress"]
    for processes in (1, 2):
        (tmp_path / str(processes)).mkdir()
        outputs = _cli_on_processes(evaluate, processes, tmp_path / str(processes))
        assert "| return" in outputs[0] and all("| return" not in o for o in outputs[1:])
        outputs = _cli_on_processes(collect, processes, tmp_path / str(processes))
        assert "stored 6 trajectories" in outputs[0] and all("stored" not in o for o in outputs[1:])
    one, two = tmp_path / "1", tmp_path / "2"
    got, want = (json.loads((d / "eval.json").read_text())["episodes"] for d in (two, one))
    assert [e["episode"] for e in got] == [e["episode"] for e in want]
    np.testing.assert_allclose([e["return"] for e in got], [e["return"] for e in want], rtol=1e-5)
    assert sorted(os.listdir(two / "videos")) == sorted(os.listdir(one / "videos")) == \
        ["eval_episode_0.mp4", "eval_episode_1.mp4"]
    stored = [[(t["episode"], float(np.sum(t["reward"]))) for t in TrajectoryDataset(d / "demos")] for d in (two, one)]
    assert len(stored[0]) == 6
    np.testing.assert_allclose(np.asarray(stored[0]), np.asarray(stored[1]), rtol=1e-5)


SHARDED_ROLLOUT = """
from jarena.platform import enable_compilation_cache
enable_compilation_cache(min_compile_secs=0)  # the suite's cache
import re, jax, numpy as np
import jarena, jarena_agents
from jarena import distributed
from jarena.runners import parallel
arena = jarena.build_arena("classic|domain:cartpole,auto_reset:lazy")
agent = jarena_agents.build_agent("random")
mesh = distributed.mesh("all")
fn = parallel._compiled(agent, arena, 8, 5, None, False, mesh, jax.random.key_impl(jax.random.key(0)))
with distributed.tracing_on(mesh):
    text = fn.lower(np.asarray(jax.random.key_data(jax.random.key(0))), None, agent.init(jax.random.key(1),
                    arena.spec, 8), arena.default_params()).compile().as_text()
print("ALL-REDUCES", len(re.findall(r"all-reduce", text)))
"""


def test_a_sharded_rollout_steps_each_devices_arenas_without_cross_device_traffic():
    # a lazy auto-reset asks "did any arena finish?" every step: on a mesh each device answers for its own
    # arenas, so the compiled rollout holds no all-reduce (the partitioner would insert one per step)
    env = _cpu_devices(4)
    output = _run_all([[sys.executable, "-c", SHARDED_ROLLOUT]], env)[0]
    assert "ALL-REDUCES 0" in output, output[-2000:]


SHARDED_EVALUATE = """
from jarena.platform import enable_compilation_cache
enable_compilation_cache(min_compile_secs=0)  # the suite's cache
import importlib, re, jax, numpy as np
import jarena, jarena_agents
from jarena import distributed
evaluate = importlib.import_module("jarena.runners.evaluate")
arena = jarena.build_arena("classic|domain:cartpole")
agent = jarena_agents.build_agent("random")
mesh = distributed.mesh("all")
fn = evaluate._compiled_episodes(agent, arena, 8, 5, None, 0, mesh, jax.random.key_impl(jax.random.key(0)))
with distributed.tracing_on(mesh):
    text = fn.lower(np.asarray(jax.random.key_data(jax.random.key(0))), agent.init(jax.random.key(1), arena.spec, 8),
                    arena.default_params(), np.arange(8, dtype=np.int32)).compile().as_text()
print("ALL-GATHERS", len(re.findall(r"all-gather", text)))
"""


def test_evaluate_keeps_each_devices_results_on_it():
    # the per-episode results stay split over the devices, each copied to the host from its own (gathered whole
    # onto every device, the compiled program held 15 all-gathers); the numbers equal one device's (tests above)
    env = _cpu_devices(4)
    output = _run_all([[sys.executable, "-c", SHARDED_EVALUATE]], env)[0]
    assert "ALL-GATHERS 0" in output, output[-2000:]


PARTITIONER = """
import jax
from jax._src import config
from jarena import distributed
with distributed.tracing_on(distributed.mesh(1)):
    one = config.use_shardy_partitioner.value
with distributed.tracing_on(distributed.mesh("all")):
    several = config.use_shardy_partitioner.value
print("SHARDY", config.use_shardy_partitioner.value, one, several)
"""


def test_sharded_calls_compile_through_gspmd_and_leave_the_default_alone():
    # XLA's CUDA plugin (jax 0.11.2) segfaults compiling MJX under shard_map over 2 GPUs through Shardy
    # (benchmarks/RESULTS.md, "Scaling over devices"): jarena's sharded calls switch to GSPMD, only inside
    env = _cpu_devices(2)
    output = _run_all([[sys.executable, "-c", PARTITIONER]], env)[0]
    assert "SHARDY True True False" in output, output[-2000:]


BC_ON_A_MESH = """
from jarena.platform import enable_compilation_cache
enable_compilation_cache(min_compile_secs=0)  # the suite's cache
import re, sys, jax, numpy as np
import jarena, jarena_agents
from jarena import distributed
from jarena.data import TrajectoryDataset, configs_for
from jarena.training import _compiled_training, train_and_evaluate
arena = jarena.build_arena("classic|domain:cartpole,task:balance")
oracle = jarena_agents.build_agent("oracle_cartpole", jarena.retrieve_config("oracle_cartpole", arena))
with TrajectoryDataset(sys.argv[1], "w", **configs_for(arena)) as dataset:
    jarena.collect(oracle, arena, dataset, 4, key=jax.random.key(1), progress=False)
agent = jarena_agents.build_agent("bc", {"dataset": sys.argv[1], "hidden": (16, 16), "batch_size": 32,
                                         "total_steps": 64})
runs = {}
for devices in ("1", "all"):
    result = train_and_evaluate(agent, arena, jax.random.key(0), chunk_updates=16, validate_every=0, progress=False,
                                devices=devices, eval_videos=0)
    runs[devices] = (jax.tree_util.tree_leaves(distributed.fetch(result.train_state.params)),
                     [h["loss"] for h in result.history])
for a, b in zip(runs["1"][0], runs["all"][0], strict=True):
    np.testing.assert_allclose(a, b, rtol=2e-4, atol=2e-5)
np.testing.assert_allclose(runs["1"][1], runs["all"][1], rtol=2e-4, atol=2e-5)
assert runs["1"][1][-1] < runs["1"][1][0]
mesh = distributed.mesh("all")
state, chunk = _compiled_training(agent, arena, jax.random.key(0), mesh)
with distributed.tracing_on(mesh):
    text = chunk.lower(state, arena, 2).compile().as_text()
print("DEVICES", mesh.devices.size, "ALL-REDUCES", len(re.findall(r"all-reduce", text)))
# diffusion: the noise and noise levels are drawn for the whole batch, then each device takes its share
pendulum = jarena.build_arena("classic|domain:pendulum,time_limit:24")
oracle = jarena_agents.build_agent("oracle_pendulum")
with TrajectoryDataset(sys.argv[1] + "-pendulum", "w", **configs_for(pendulum)) as dataset:
    jarena.collect(oracle, pendulum, dataset, 4, key=jax.random.key(1), progress=False)
agent = jarena_agents.build_agent("diffusion", dict(dataset=sys.argv[1] + "-pendulum", down_dims=(8,), groups=2,
                                                    step_embedding=16, horizon=8, obs_horizon=2, action_steps=4,
                                                    batch_size=32, learning_rate=1e-2, warmup_steps=4,
                                                    total_steps=32))
runs = {}
for devices in ("1", "all"):
    result = train_and_evaluate(agent, pendulum, jax.random.key(0), chunk_updates=16, validate_every=0,
                                progress=False, devices=devices, eval_videos=0)
    runs[devices] = (jax.tree_util.tree_leaves(distributed.fetch(result.train_state.params)),
                     [h["loss"] for h in result.history])
for a, b in zip(runs["1"][0], runs["all"][0], strict=True):
    np.testing.assert_allclose(a, b, rtol=2e-4, atol=2e-5)
np.testing.assert_allclose(runs["1"][1], runs["all"][1], rtol=2e-4, atol=2e-5)
state, chunk = _compiled_training(agent, pendulum, jax.random.key(0), mesh)
with distributed.tracing_on(mesh):
    text = chunk.lower(state, pendulum, 2).compile().as_text()
print("DIFFUSION ALL-REDUCES", len(re.findall(r"all-reduce", text)))
"""


def test_bc_and_diffusion_split_their_minibatches_over_the_devices_and_train_as_one_device(tmp_path):
    # bc and diffusion sample their minibatches from a replicated dataset: on a mesh each device computes the loss
    # of its share and XLA sums the gradients (all-reduces; a replicated minibatch compiles to none), and the run's
    # parameters and losses are one device's
    env = _cpu_devices(4)
    output = _run_all([[sys.executable, "-c", BC_ON_A_MESH, str(tmp_path / "demos")]], env)[0]
    found = re.search(r"DEVICES 4 ALL-REDUCES (\d+)", output)
    assert found and int(found.group(1)) > 0, output[-2000:]
    found = re.search(r"DIFFUSION ALL-REDUCES (\d+)", output)  # diffusion splits its batch the same way
    assert found and int(found.group(1)) > 0, output[-2000:]


def test_split_batch_leaves_arrays_alone_without_a_mesh():
    x = jax.numpy.arange(8.0)
    assert distributed.split_batch({"x": x})["x"] is x


def test_launch_checks_its_values():
    with pytest.raises(ValueError, match="HOST:PORT"):
        distributed.Launch("localhost", 2, 0)
    with pytest.raises(ValueError, match="process_id must be in 0 .. 1"):
        distributed.Launch("localhost:1234", 2, 2)
    with pytest.raises(ValueError, match="num_processes"):
        distributed.Launch("localhost:1234", 0, 0)


def test_launch_from_environment_needs_all_three_variables(monkeypatch):
    for var in distributed.ENVIRONMENT.values():
        monkeypatch.delenv(var, raising=False)
    assert distributed.launch_from_environment() is None
    monkeypatch.setenv("JARENA_COORDINATOR", "localhost:1234")
    with pytest.raises(ValueError, match="missing JARENA_NUM_PROCESSES, JARENA_PROCESS_ID"):
        distributed.launch_from_environment()
    monkeypatch.setenv("JARENA_NUM_PROCESSES", "2")
    monkeypatch.setenv("JARENA_PROCESS_ID", "1")
    assert distributed.launch_from_environment() == distributed.Launch("localhost:1234", 2, 1)


def test_mesh_names_the_valid_device_counts():
    assert distributed.mesh().devices.size == 1  # one process: one device unless asked
    assert distributed.mesh("all").devices.size == len(jax.devices())
    with pytest.raises(ValueError, match=f"choose 'all' or a count from 1 to {len(jax.devices())}"):
        distributed.mesh(len(jax.devices()) + 1)
    with pytest.raises(ValueError, match="'all' or a positive integer"):
        distributed.mesh("many")


def test_batch_shardings_split_the_arena_axis_and_replicate_the_rest():
    mesh = distributed.mesh("all")
    tree = {"params": np.zeros((3, 8)), "arenas": np.zeros((8, 5)), "step": np.zeros(())}
    shardings = distributed.batch_shardings(tree, mesh, 8)
    assert shardings["params"].spec == shardings["step"].spec == jax.sharding.PartitionSpec()
    expected = jax.sharding.PartitionSpec("data") if mesh.devices.size > 1 else jax.sharding.PartitionSpec()
    assert shardings["arenas"].spec == expected


def test_network_parameters_as_wide_as_the_arena_count_stay_whole():
    """PPO on 8 arenas with 8-unit layers: the arenas' state is split, every parameter and optimiser moment (under
    Flax's "params" key) is replicated although its leading axis is 8 (split, each gradient step gathered them)."""
    import jarena
    import jarena_agents

    mesh = jax.sharding.AbstractMesh((4,), (distributed.AXIS,))  # the layout of 4 devices, planned without them
    arena = jarena.build_arena("classic|domain:cartpole")
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 8, "hidden": [8, 8], "minibatches": 1})
    shapes = jax.eval_shape(lambda key: agent.init_training(key, arena), jax.random.key(0))
    shardings = distributed.batch_shardings(shapes, mesh, 8)
    whole, split = jax.sharding.PartitionSpec(), jax.sharding.PartitionSpec("data")
    rows = [(jax.tree_util.keystr(path), x.shape, sharding.spec) for (path, x), sharding in
            zip(jax.tree_util.tree_leaves_with_path(shapes), jax.tree_util.tree_leaves(shardings), strict=True)]
    wide = [(p, spec) for p, shape, spec in rows if "['params']" in p and shape[:1] == (8,)]
    assert len(wide) >= 12 and all(spec == whole for _, spec in wide)  # weights, biases, Adam's mu and nu
    arenas = [spec for p, shape, spec in rows if p.startswith(".arena_state") and shape[:1] == (8,)]
    assert arenas and all(spec == split for spec in arenas)


def test_an_arena_count_that_does_not_split_evenly_is_refused():
    three_devices = jax.sharding.AbstractMesh((3,), (distributed.AXIS,))
    with pytest.raises(ValueError, match="8 arenas cannot be split evenly over 3 devices"):
        distributed.batch_shardings({"x": np.zeros(8)}, three_devices, 8)
