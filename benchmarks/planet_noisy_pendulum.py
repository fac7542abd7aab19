"""Which demonstrations an offline world model plans best from: PlaNet learned from a dataset of the pendulum (action
repeat 4) made of 16 oracle swing-ups plus 16 episodes of random actions, of the oracle acting with noise
(``jarena_agents.noisy``), or of the oracle alone, then CEM over the learned model on the first 8 eval episodes.
The model, training and planner are ``tests/agents/planet/test_offline.py``'s (1,000 gradient steps of a small
model); a CPU-sized check of what ``benchmarks/planet_cloth.py --noisy`` does on cloth.

    python benchmarks/planet_noisy_pendulum.py --seeds 0,1,2
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import jarena
import jarena_agents
from jarena.data import TrajectoryDataset
from jarena.runners.evaluate import evaluate

ARENA = "classic|domain:pendulum,action:repeat(4)"
MODEL = dict(batch_size=16, sequence_length=16, total_steps=1000, deter=32, stoch=4, classes=8, hidden=32, layers=1,
             bins=41, model_learning_rate=1e-3, horizon=12, samples=100, iterations=4)


def dataset(path: Path, arena, second: str, noise: float, random_actions: float) -> str:
    oracle = jarena_agents.build_agent("oracle_pendulum")
    make = {"random": lambda: jarena_agents.build_agent("random"), "oracle": lambda: oracle,
            "noisy": lambda: jarena_agents.noisy(oracle, action_noise=noise, random_fraction=random_actions)}
    others = make[second]()
    with TrajectoryDataset(path, "w", **jarena.data.configs_for(arena)) as data:
        jarena.data.collect(oracle, arena, data, 16, key=jax.random.key(0), progress=False)
        jarena.data.collect(others, arena, data, 16, key=jax.random.key(1), progress=False)
    return str(path)


def planned_return(arena, data: str, seed: int) -> float:
    agent = jarena_agents.build_agent("planet", dict(MODEL, dataset=data))
    state = jax.jit(agent.init_training, static_argnums=1)(jax.random.key(seed), arena)
    state, _ = jax.jit(lambda ts: agent.train(ts, arena, 1000))(state)
    result = evaluate(agent, arena, jax.random.key(1), agent_state=agent.policy(state, arena.spec, True),
                      episodes=np.arange(8))
    return result.summary()["return_mean"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="0,1,2", help="model init keys")
    parser.add_argument("--noise", type=float, default=0.3, help="the noisy oracle's action noise (half ranges)")
    parser.add_argument("--random-actions", type=float, default=0.3, help="the noisy oracle's random fraction")
    parser.add_argument("--second", default="random,noisy,oracle", help="what follows the 16 oracle episodes")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    arena = jarena.build_arena(ARENA)
    print(f"{platform.processor() or platform.machine()}, jax {jax.__version__}, {jax.devices()[0].platform}")
    random = evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(1), episodes=np.arange(8))
    print(f"random actions on the 8 eval episodes: {random.summary()['return_mean']:.0f}")
    print("| 16 oracle episodes + 16 of | " + " | ".join(f"seed {s}" for s in seeds) + " | mean | seconds |")
    print("|---|" + "---:|" * (len(seeds) + 2))
    with tempfile.TemporaryDirectory() as tmp:
        for second in args.second.split(","):
            start = time.perf_counter()
            data = dataset(Path(tmp) / second, arena, second, args.noise, args.random_actions)
            returns = [planned_return(arena, data, seed) for seed in seeds]
            label = (f"the oracle with noise {args.noise:g}, {args.random_actions:.0%} random" if second == "noisy"
                     else {"random": "random actions", "oracle": "the oracle"}[second])
            print(f"| {label} | " + " | ".join(f"{r:.0f}" for r in returns) + f" | **{np.mean(returns):.0f}** | "
                  f"{time.perf_counter() - start:.0f} |", flush=True)


if __name__ == "__main__":
    main()
