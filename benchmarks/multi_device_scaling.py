"""Scaling over devices: perform_parallel rollouts and PPO training on 1 device against all local devices.

Weak scaling keeps the arenas per device fixed (the batch grows with the devices); strong scaling keeps the
global batch fixed. For each device count it reports rollout steps/s (a random agent, ``perform_parallel``,
``record=False``, the compiled call timed after a warm-up), ``evaluate`` steps/s (the same agent, one episode
per arena capped at the rollout's steps, host results included) and PPO training steps/s (``train_and_evaluate``
on the mesh, from the chunks after the first, so compilation is excluded), and the ratio to one device.

    python benchmarks/multi_device_scaling.py --arena "dmc|domain:walker,task:walk" --arenas 2048 \
        --rollout-steps 100 --ppo-steps 2000000
    # on a CPU, rehearse with split devices:
    XLA_FLAGS=--xla_force_host_platform_device_count=4 python benchmarks/multi_device_scaling.py --ppo-steps 0

Prints one line per measurement and a JSON summary (with the machine) at the end.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import numpy as np
from timing import environment

import jarena
import jarena_agents
from jarena.cli import parse_override
from jarena.training import train_and_evaluate


def rollout_rate(arena, num_arenas: int, steps: int, devices: int, repeats: int) -> float:
    """Agent steps per second of a random agent's rollout over ``devices`` devices (best of ``repeats``)."""
    agent = jarena_agents.build_agent("random")
    key = jax.random.key(0)
    jax.block_until_ready(jarena.perform_parallel(agent, arena, key, num_arenas, steps, record=False,
                                                  devices=devices).info.reward)  # compile and warm up
    best = float("inf")
    for i in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(jarena.perform_parallel(agent, arena, jax.random.key(i + 1), num_arenas, steps,
                                                      record=False, devices=devices).info.reward)
        best = min(best, time.perf_counter() - t0)
    return num_arenas * steps / best


def evaluate_rate(arena, num_episodes: int, steps: int, devices: int, repeats: int) -> float:
    """Agent steps per second of ``evaluate`` (a random agent, ``num_episodes`` episodes capped at ``steps``)."""
    agent = jarena_agents.build_agent("random")
    episodes = np.arange(num_episodes)

    def once(seed):
        t0 = time.perf_counter()
        result = jarena.evaluate(agent, arena, jax.random.key(seed), episodes=episodes, max_steps=steps,
                                 devices=devices)  # returns host arrays: the call has finished
        return time.perf_counter() - t0, int(result.lengths.sum())

    once(0)  # compile and warm up
    best = min(once(i + 1) for i in range(repeats))
    return best[1] / best[0]


def ppo_rate(arena, config: dict, num_arenas: int, total_steps: int, devices: int, seed: int = 0
             ) -> tuple[float, float]:
    """``(environment steps/s after the first chunk, final eval return)`` of PPO on ``devices`` devices."""
    agent = jarena_agents.build_agent("ppo", dict(config, num_arenas=num_arenas, total_steps=total_steps))
    updates = agent.settings.num_updates
    if updates < 2:
        raise SystemExit(f"--ppo-steps {total_steps} is {updates} PPO update of {agent.settings.steps_per_update} "
                         "steps; the rate is measured after the first chunk: give at least 2 updates' worth")
    result = train_and_evaluate(agent, arena, jax.random.key(seed), validate_every=0, progress=False, eval_videos=0,
                                devices=devices, chunk_updates=max(1, updates // 10))
    first, last = result.history[0], result.history[-1]
    rate = (last["env_steps"] - first["env_steps"]) / max(last["seconds"] - first["seconds"], 1e-9)
    return rate, result.evaluation.summary()["return_mean"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arena", default="classic|domain:cartpole")
    parser.add_argument("--arenas", type=int, default=4096, help="arenas per device (weak) and in all (strong)")
    parser.add_argument("--rollout-steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--ppo-steps", type=int, default=0, help="PPO environment steps per run (0: no PPO)")
    parser.add_argument("--ppo-config", default="default", help="config name under configs/ppo/<arena>/")
    parser.add_argument("--ppo-set", action="append", type=parse_override, default=[], metavar="KEY=VALUE",
                        help="a PPO setting over the config (value as YAML), e.g. minibatches=8; repeatable")
    parser.add_argument("--seeds", default="0", help="PPO seeds, comma-separated: each device count trains once per "
                        "seed (rate: the mean; return: every seed's, then mean and spread)")
    parser.add_argument("--devices", default="1,all", help="device counts to compare, the first the baseline")
    parser.add_argument("--measure", default="rollout,evaluate",
                        help="what to time besides PPO (which --ppo-steps turns on): rollout, evaluate, both (default) "
                             "or none")
    parser.add_argument("--scaling", default="weak,strong", help="which to measure: weak, strong or both (default)")
    args = parser.parse_args()
    arena = jarena.build_arena(args.arena)
    seeds = [int(s) for s in args.seeds.split(",")]
    counts = sorted({int(c) if c != "all" else len(jax.local_devices()) for c in args.devices.split(",")})
    config = jarena.retrieve_config("ppo", arena, args.ppo_config) if args.ppo_steps else None
    if config is not None:
        config = dict(config, **dict(args.ppo_set))
    measures = set(args.measure.split(",")) - {"none"}
    if measures - {"rollout", "evaluate"}:
        raise SystemExit(f"--measure {args.measure!r}: give rollout, evaluate, rollout,evaluate or none")
    scalings = [s for s in ("weak", "strong") if s in args.scaling.split(",")]
    if not scalings or set(args.scaling.split(",")) - {"weak", "strong"}:
        raise SystemExit(f"--scaling {args.scaling!r}: give weak, strong or weak,strong")
    if args.ppo_steps:  # the largest batch must still make 2 updates: check before any run
        largest_batch = args.arenas * (counts[-1] if "weak" in scalings else 1)
        largest = jarena_agents.build_agent("ppo", dict(config, num_arenas=largest_batch,
                                                       total_steps=args.ppo_steps)).settings
        if largest.num_updates < 2:
            raise SystemExit(f"--ppo-steps {args.ppo_steps} is {largest.num_updates} PPO update of "
                             f"{largest.steps_per_update} steps at {largest_batch} arenas; the rate is "
                             "measured after the first chunk: give at least 2 updates' worth")
    results = {}
    for scaling in scalings:
        for d in counts:
            n = args.arenas * d if scaling == "weak" else args.arenas
            if f"weak/{d}" in results and d == counts[0]:  # the baseline: the same run for both
                results[f"{scaling}/{d}"] = results[f"weak/{d}"]
                continue
            row = {"devices": d, "arenas": n}
            if "rollout" in measures:
                row["rollout_steps_per_s"] = rollout_rate(arena, n, args.rollout_steps, d, args.repeats)
            if "evaluate" in measures:
                row["evaluate_steps_per_s"] = evaluate_rate(arena, n, args.rollout_steps, d, args.repeats)
            if args.ppo_steps:
                runs = [ppo_rate(arena, config, n, args.ppo_steps, d, seed) for seed in seeds]
                row["ppo_steps_per_s"] = float(np.mean([rate for rate, _ in runs]))
                row["ppo_returns"] = [ret for _, ret in runs]
                row["ppo_return"] = float(np.mean(row["ppo_returns"]))
            results[f"{scaling}/{d}"] = row
            base = results[f"{scaling}/{counts[0]}"]
            rates = [f"{what} {row[f'{what}_steps_per_s']:.4g} steps/s "
                     f"({row[f'{what}_steps_per_s'] / base[f'{what}_steps_per_s']:.2f}x)"
                     for what in ("rollout", "evaluate", "ppo") if f"{what}_steps_per_s" in row]
            if args.ppo_steps:
                rates.append(f"return {row['ppo_return']:.1f}")
                if len(seeds) > 1:
                    rates[-1] += " (seeds " + ", ".join(f"{r:.1f}" for r in row["ppo_returns"]) + ")"
            print(f"{scaling:6s} {d} device(s) {n:8d} arenas: " + ", ".join(rates), flush=True)
    print(json.dumps({"results": results, "environment": environment(arena=args.arena,
                                                                      devices=len(jax.local_devices()))}, indent=2))


if __name__ == "__main__":
    main()
