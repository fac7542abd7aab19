"""PPO on classic cartpole: wall-clock of whole training runs, one seed and many vmapped seeds.

Each run is ``agent.train(agent.init_training(key, arena), arena, num_updates)`` in one compiled call
(compile timed apart); with S seeds the run is ``jax.vmap``-ed over S keys. Reports training seconds,
env-steps per second over all seeds, and the deterministic policy's mean return on the 100 eval
episodes for the first few seeds (``jarena.evaluate``).

    python benchmarks/ppo_cartpole.py --seeds 1,1024 --steps 500000
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import jarena
import jarena_agents


def main() -> None:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="1,1024", help="comma-separated numbers of vmapped seeds")
    parser.add_argument("--steps", type=int, default=500_000, help="environment steps per seed")
    parser.add_argument("--eval-seeds", type=int, default=8, help="seeds evaluated on the eval episodes")
    args = parser.parse_args()

    arena = jarena.build_arena("classic|domain:cartpole,task:balance")
    config = dict(jarena.retrieve_config("ppo", arena), total_steps=args.steps)
    agent = jarena_agents.build_agent("ppo", config)
    updates = agent.settings.num_updates
    print(f"# PPO on {arena.build_string}, {updates * agent.settings.steps_per_update} steps per seed, "
          f"device {jax.devices()[0].device_kind}, jax {jax.__version__}")
    print("| seeds | compile s | train s | env-steps/s (all seeds) | eval return (mean over seeds) | min |")
    print("|---|---|---|---|---|---|")
    for seeds in [int(s) for s in args.seeds.split(",")]:
        def run(keys):
            return jax.vmap(lambda k: agent.train(agent.init_training(k, arena), arena, updates)[0])(keys)

        keys = jax.random.split(jax.random.key(0), seeds)
        start = time.perf_counter()
        compiled = jax.jit(run).lower(keys).compile()
        compile_s = time.perf_counter() - start
        start = time.perf_counter()
        states = jax.block_until_ready(compiled(keys))
        train_s = time.perf_counter() - start
        returns = []
        for i in range(min(seeds, args.eval_seeds)):
            state = jax.tree_util.tree_map(lambda x, i=i: x[i], states)
            result = jarena.evaluate(agent, arena, jax.random.key(1), agent_state=agent.policy(state, arena.spec))
            returns.append(result.summary()["return_mean"])
        steps = seeds * updates * agent.settings.steps_per_update
        print(f"| {seeds} | {compile_s:.1f} | {train_s:.2f} | {steps / train_s:.3g} | {np.mean(returns):.1f} "
              f"| {np.min(returns):.1f} |", flush=True)


if __name__ == "__main__":
    main()
