"""P policies of one agent evaluated one after another (``jarena.evaluate`` each) against all at once
(``jarena.evaluate_policies``, one batch of P x N arenas): seconds per call after a compiling call, best of
``--repeats``, whether the per-episode returns are equal, and each policy's mean return both ways (batched
operations may round differently, which chaotic physics such as a walker's can grow). The policies are PPO's
initial networks from P keys, acting greedily (what is timed is the evaluation loop, not what the policies learned).

    python benchmarks/evaluate_policies_speed.py --arena "dmc|domain:walker,task:walk,time_limit:200" --policies 3
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np

import jarena
import jarena_agents


def best_seconds(fn, repeats: int) -> float:
    fn()  # compiles
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arena", default="classic|domain:cartpole")
    parser.add_argument("--policies", type=int, default=3)
    parser.add_argument("--split", default="val", choices=("val", "eval"))
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    arena = jarena.build_arena(args.arena)
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "total_steps": 4096})
    policies = [agent.policy(agent.init_training(jax.random.key(p), arena), arena.spec, True)
                for p in range(args.policies)]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *policies)
    key = jax.random.key(0)

    def one_by_one():
        return [jarena.evaluate(agent, arena, key, agent_state=p, split=args.split) for p in policies]

    def together():
        return jarena.evaluate_policies(agent, arena, stacked, key, split=args.split)

    pairs = list(zip(one_by_one(), together(), strict=True))
    equal = all(np.array_equal(a.returns, b.returns) for a, b in pairs)
    mean_returns = [[round(float(a.returns.mean()), 3), round(float(b.returns.mean()), 3)] for a, b in pairs]
    apart, at_once = best_seconds(one_by_one, args.repeats), best_seconds(together, args.repeats)
    print(json.dumps({"arena": args.arena, "policies": args.policies, "split": args.split,
                      "episodes": len(arena.episodes(args.split)), "one_by_one_s": round(apart, 3),
                      "together_s": round(at_once, 3), "speedup": round(apart / at_once, 2), "equal": equal,
                      "mean_returns_apart_together": mean_returns,
                      "device": jax.devices()[0].device_kind, "jax": jax.__version__}))


if __name__ == "__main__":
    main()
