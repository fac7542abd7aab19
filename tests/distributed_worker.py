"""One process of a data-parallel training run, started by ``test_distributed.py`` (not a test itself).

Usage: ``python distributed_worker.py OUT AGENT DEVICES [COORDINATOR NUM_PROCESSES PROCESS_ID]
[--stop-after CHUNKS]``. Trains ``AGENT`` (``ppo`` or ``sac``, small configs) on classic cartpole or
pendulum with ``train_and_evaluate(devices=DEVICES)`` and ``run_dir=OUT/run``, and writes what the test
compares to ``OUT/result_<process>.npz``: the final train state, the training history, the evaluation, and
the evaluation of one fixed sampling policy on the same devices.
The test sets ``XLA_FLAGS`` to split the CPU into devices.
"""

import argparse
import json
import sys

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("agent", choices=["ppo", "sac"])
parser.add_argument("devices")
parser.add_argument("launch", nargs="*")
parser.add_argument("--stop-after", type=int, default=None)
args = parser.parse_args()

from jarena import distributed  # noqa: E402

if args.launch:
    coordinator, processes, process = args.launch
    distributed.initialize(distributed.Launch(coordinator, int(processes), int(process)))

import jax  # noqa: E402
import numpy as np  # noqa: E402

import jarena  # noqa: E402
import jarena_agents  # noqa: E402
from jarena.platform import enable_compilation_cache  # noqa: E402
from jarena.runners.evaluate import evaluate  # noqa: E402
from jarena.training import train_and_evaluate  # noqa: E402

enable_compilation_cache(min_compile_secs=0)  # every program, as the suite (tests/conftest.py)
# 16 evaluation and 8 validation episodes (the arenas' default 100 and 20 cost most of a multi-process run, whose
# every evaluation step waits on the other processes): each still splits evenly over up to 8 devices
SPLITS = ",eval_episodes:16,val_episodes:8"
CONFIGS = {
    "ppo": ("classic|domain:cartpole,auto_reset:lazy" + SPLITS,  # lazy: a cond per step, kept on each device
            {"num_arenas": 8, "rollout_length": 16, "total_steps": 8 * 16 * 4, "minibatches": 2, "epochs": 2}),
    "sac": ("classic|domain:pendulum" + SPLITS,
            {"num_arenas": 4, "rollout_length": 4, "total_steps": 4 * 4 * 4, "batch_size": 32, "buffer_size": 256,
             "learning_starts": 16, "hidden": (32, 32)}),
}
arena_string, config = CONFIGS[args.agent]
arena = jarena.build_arena(arena_string)
agent = jarena_agents.build_agent(args.agent, config)
result = train_and_evaluate(agent, arena, jax.random.key(0), chunk_updates=1, validate_every=1, progress=False,
                            devices=args.devices, run_dir=f"{args.out}/run", checkpoint_every=1,
                            stop_after_chunks=args.stop_after, eval_videos=0)
if result.evaluation is None:  # stopped: the checkpoints are what the next launch resumes from (and compares)
    sys.exit(0)
# a random agent's rollout on the run's devices: the same steps as on one device
rollout = jarena.perform_parallel(jarena_agents.build_agent("random"), arena, jax.random.key(3), 8, 40,
                                  devices=args.devices)
rollout_steps = distributed.fetch((rollout.infos.reward, rollout.infos.done, rollout.infos.observation))
rollout_shards = max(len(x.sharding.device_set) for x in jax.tree_util.tree_leaves(rollout.state) if x.ndim)
# collect: 6 random trajectories from 8 arenas split over the devices; only process 0 opens and writes
dataset = (jarena.TrajectoryDataset(f"{args.out}/data", "w", **jarena.data.configs_for(arena))
           if distributed.is_main_process() else None)
stored = jarena.collect(jarena_agents.build_agent("random"), arena, dataset, 6, key=jax.random.key(4), num_arenas=8,
                        chunk_steps=50, progress=False, devices=args.devices)
collected = np.zeros((0, 2))
if dataset is not None:
    collected = np.asarray([[t["episode"], np.sum(t["reward"])] for t in dataset], np.float64)
    assert stored == list(range(6)), stored
    dataset.close()
else:
    assert stored == [], stored
# one fixed (untrained, sampling) policy evaluated on the run's devices: evaluation alone must be exact
untrained = jax.device_get(agent.policy(jax.jit(agent.init_training, static_argnums=1)(jax.random.key(1), arena),
                                        arena.spec, False))
fixed = evaluate(agent, arena, jax.random.key(2), agent_state=untrained, devices=args.devices)
leaves = jax.tree_util.tree_leaves(distributed.fetch(result.train_state))
leaves = [jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x for x in leaves]
batch = [x for x in jax.tree_util.tree_leaves(result.train_state)
         if isinstance(x, jax.Array) and x.ndim and x.shape[0] == config["num_arenas"]]
np.savez(f"{args.out}/result_{jax.process_index()}.npz",
         *[np.asarray(x) for x in leaves],
         history=json.dumps(result.history), evaluation=np.asarray(result.evaluation.returns),
         rollout_steps=np.concatenate([np.asarray(x, np.float32).reshape(40, 8, -1)
                                       for x in jax.tree_util.tree_leaves(rollout_steps)], axis=-1),
         rollout_shards=rollout_shards, collected=collected, fixed_policy_returns=fixed.returns,
         fixed_policy_lengths=fixed.lengths,
         devices=len(jax.devices()), processes=jax.process_count(),
         batch_shards=min(len(x.sharding.device_set) for x in batch))
