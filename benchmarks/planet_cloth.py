"""Offline PlaNet against BC (and Diffusion Policy) on cloth flattening from pixels, all trained on the same dataset:
collection, training and the final normalised coverage after ``--actions`` pick-and-places on the eval episodes, with
the wall time of each part. Made for a GPU (the committed configs: 50,000 PlaNet updates, 20,000 BC updates, 20,000
diffusion updates).

    python benchmarks/planet_cloth.py --demos 256 --run-dir runs/planet_cloth

1. ``jarena.collect``: ``--demos`` episodes of ``oracle_cloth_flattening`` (training episodes) into a dataset, then
   ``--noisy`` episodes of the same oracle acting with noise (``jarena_agents.noisy``: ``--action-noise`` half
   ranges of Gaussian noise, ``--random-actions`` of its actions uniformly random; Agent-Arena's cloth datasets mix
   oracle demonstrations with noisier ones so), then ``--random`` episodes of the ``random`` agent (default neither:
   the oracle's demonstrations alone, as bc's cloth results were collected; a world model may need the others, see
   docs/agents/planet.md);
   ``--set-oracle KEY=VALUE`` sets the oracle's config keys (e.g. ``interior=0 outward=0.15 tips=false``, the
   lookahead of 2026-11-25 that bc's first cloth results cloned);
2. ``train_and_evaluate``: each of ``--agents`` (default ``planet,bc``; also ``diffusion`` and ``transporter``, which
   here sees the RGB image with a zero height channel, as the arena renders no depth) offline on that dataset
   from its committed config (``configs/<agent>/cloth-square_fabric-flattening``), each evaluated with its final
   policy on the ``--episodes`` eval episodes (no validation);
3. the ``random`` agent on the same eval episodes.

The arena is bc's of benchmarks/RESULTS.md ("BC from pixels on cloth flattening"): ``cloth|domain:square_fabric,
initial:crumpled,particles:40,resolution:64,depth:false,mask:false,horizon:10``. Prints a table: per agent the
updates, training seconds (compilation included), updates per second after the first chunk, evaluation seconds, the
mean final normalised coverage (after the episode's last action), the episodes at 0.9 or more, the success rate
(0.99) and the return. ``--set-planet KEY=VALUE`` / ``--set-bc`` / ``--set-diffusion`` override config keys;
``--particles``, ``--resolution`` and the step counts make a small run for a smoke test on a CPU:

    python benchmarks/planet_cloth.py --demos 4 --particles 8 --resolution 16 --actions 3 --episodes 4 \\
        --planet-steps 20 --bc-steps 20 --set-planet cnn_layers=2 --set-planet samples=16 --set-planet iterations=2 \\
        --set-planet sequence_length=3
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
import yaml

import jarena
import jarena_agents
from jarena.data import TrajectoryDataset, configs_for
from jarena.platform import enable_compilation_cache
from jarena.runners.evaluate import evaluate
from jarena.training import train_and_evaluate

#: The agents this script trains from the dataset, each from its committed cloth config.
AGENTS = ("planet", "bc", "diffusion", "transporter")


def arena_string(particles: int, resolution: int, actions: int, episodes: int) -> str:
    return (f"cloth|domain:square_fabric,initial:crumpled,particles:{particles},resolution:{resolution},depth:false,"
            f"mask:false,horizon:{actions},eval_episodes:{episodes},action:pixel_pick_and_place(1),task:flattening")


def overrides(items: list[str]) -> dict:
    return {k: yaml.safe_load(v) for k, v in (item.split("=", 1) for item in items)}


def collect(arena, path: Path, demos: int, random: int, seed: int, batch: int, oracle_config: dict,
            noisy: int = 0, action_noise: float = 0.1, random_actions: float = 0.1) -> dict:
    """Writes the dataset; returns what it holds and the seconds it took."""
    start = time.perf_counter()
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        oracle = jarena_agents.build_agent("oracle_cloth_flattening", dict(oracle_config, arena=arena.build_string))
        jarena.collect(oracle, arena, dataset, demos, key=jax.random.key(seed + 1_000), num_arenas=min(batch, demos),
                       progress=False)
        oracle_s = time.perf_counter() - start
        if noisy:
            jarena.collect(jarena_agents.noisy(oracle, action_noise=action_noise, random_fraction=random_actions),
                           arena, dataset, noisy, key=jax.random.key(seed + 3_000), num_arenas=min(batch, noisy),
                           progress=False)
        if random:
            jarena.collect(jarena_agents.build_agent("random"), arena, dataset, random,
                           key=jax.random.key(seed + 2_000), num_arenas=min(batch, random), progress=False)
        lengths = dataset.lengths()
        rewards = dataset.rows("step/reward", 0, dataset.num_steps()).astype(np.float64)
        finals = rewards[np.cumsum(lengths) - 1]  # the normalised coverage after each episode's last action
    return dict(trajectories=int(lengths.size), steps=int(lengths.sum()), oracle_final=float(finals[:demos].mean()),
                noisy_final=float(finals[demos:demos + noisy].mean()) if noisy else None,
                random_final=float(finals[demos + noisy:].mean()) if random else None, oracle_s=oracle_s,
                seconds=time.perf_counter() - start)


def row(name: str, result, updates: int, seconds: float) -> dict:
    """The table row of an agent trained (``result``: a TrainResult) or evaluated (an EvalResult)."""
    evaluation = getattr(result, "evaluation", result)
    coverage = evaluation.metrics["normalised_coverage"]
    out = dict(agent=name, updates=updates, train_s=None, updates_per_s=None, evaluate_s=seconds,
               final_coverage=float(np.mean(coverage)), reach_90=int(np.sum(coverage >= 0.9)),
               episodes=int(coverage.size), success_rate=float(np.mean(evaluation.successes)),
               return_mean=float(np.mean(evaluation.returns)))
    history = getattr(result, "history", None)
    if history:
        train_s = history[-1]["seconds"]
        steady = (history[-1]["update"] - history[0]["update"]) / max(train_s - history[0]["seconds"], 1e-9)
        out.update(train_s=train_s, evaluate_s=seconds - train_s,
                   updates_per_s=steady if len(history) > 1 else None,
                   loss_first=history[0].get("model_loss", history[0].get("loss")),
                   loss_last=history[-1].get("model_loss", history[-1].get("loss")))
    return out


def train(name: str, arena, dataset: Path, config: dict, seed: int, run_dir: Path, devices) -> dict:
    """Trains ``name`` on the dataset from its committed config updated by ``config``; returns its table row."""
    full = dict(jarena.retrieve_config(name, arena), **config, dataset=str(dataset))
    agent = jarena_agents.build_agent(name, full)
    start = time.perf_counter()
    result = train_and_evaluate(agent, arena, jax.random.key(seed), run_dir=run_dir, progress=False, eval_videos=0,
                                validate_every=0, devices=devices)
    out = row(name, result, agent.settings.num_updates, time.perf_counter() - start)
    print(f"{name}: {json.dumps(out)}", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--demos", type=int, default=256, help="oracle episodes (bc's cloth results: 256)")
    parser.add_argument("--noisy", type=int, default=0, help="noisy-oracle episodes appended to the dataset")
    parser.add_argument("--action-noise", type=float, default=0.1,
                        help="the noisy oracle's Gaussian noise, in half ranges of the action box")
    parser.add_argument("--random-actions", type=float, default=0.1,
                        help="the noisy oracle's fraction of uniformly random actions")
    parser.add_argument("--random", type=int, default=0, help="random-agent episodes appended to the dataset")
    parser.add_argument("--particles", type=int, default=40, help="cloth particles along a side")
    parser.add_argument("--resolution", type=int, default=64, help="camera resolution (pixels along a side)")
    parser.add_argument("--actions", type=int, default=10, help="pick-and-place actions per episode")
    parser.add_argument("--episodes", type=int, default=128, help="eval episodes")
    parser.add_argument("--batch", type=int, default=128, help="arenas collected in parallel")
    for name in AGENTS:
        parser.add_argument(f"--{name}-steps", type=int, default=None,
                            help=f"{name}'s gradient updates (default: config)")
        parser.add_argument(f"--set-{name}", action="append", default=[], metavar="KEY=VALUE",
                            help=f"{name} config key")
    parser.add_argument("--agents", default="planet,bc", help=f"comma-separated agents to train: {', '.join(AGENTS)}")
    parser.add_argument("--set-oracle", action="append", default=[], metavar="KEY=VALUE",
                        help="oracle_cloth_flattening config key (the demonstrations' oracle)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--devices", default=None, help="train data-parallel on N devices, or 'all'")
    parser.add_argument("--run-dir", default=None, help="keep the dataset, logs and results here")
    args = parser.parse_args()
    cache = enable_compilation_cache()  # as the jarena command: a rerun loads its programs instead of compiling
    print(f"compilation cache: {cache or 'off'}", flush=True)
    devices = args.devices if args.devices in (None, "all") else int(args.devices)
    print(f"{jax.devices()[0].device_kind}, jax {jax.__version__}, Python {platform.python_version()}", flush=True)
    agents = args.agents.split(",")
    unknown = sorted(set(agents) - set(AGENTS))
    if unknown:
        parser.error(f"unknown agents {unknown}; choose from {', '.join(AGENTS)}")
    configs = {name: overrides(getattr(args, f"set_{name}")) for name in AGENTS}
    for name in AGENTS:
        steps = getattr(args, f"{name}_steps")
        if steps is not None:
            configs[name]["total_steps"] = steps
    oracle_config = overrides(args.set_oracle)

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.run_dir or tmp)
        root.mkdir(parents=True, exist_ok=True)
        arena = jarena.build_arena(arena_string(args.particles, args.resolution, args.actions, args.episodes))
        print(f"arena: {arena.build_string}", flush=True)
        data = root / f"cloth_{args.demos}_oracle_{args.noisy}_noisy_{args.random}_random"
        held = collect(arena, data, args.demos, args.random, args.seed, args.batch, oracle_config, args.noisy,
                       args.action_noise, args.random_actions)
        print(f"collected {held['trajectories']} episodes ({held['steps']} actions) in {held['seconds']:.1f} s "
              f"(oracle {held['oracle_s']:.1f} s): final coverage {held['oracle_final']:.3f} (oracle)"
              + (f", {held['noisy_final']:.3f} (noisy oracle)" if args.noisy else "")
              + (f", {held['random_final']:.3f} (random)" if args.random else ""), flush=True)
        rows = [train(name, arena, data, configs[name], args.seed, root / name, devices) for name in agents]
        start = time.perf_counter()
        rows.append(row("random", evaluate(jarena_agents.build_agent("random"), arena, jax.random.key(args.seed)),
                        0, time.perf_counter() - start))

    print(f"\n{held['trajectories']} episodes ({args.demos} oracle, {args.noisy} noisy oracle (noise "
          f"{args.action_noise}, random {args.random_actions}), {args.random} random), {args.episodes} eval "
          f"episodes, {args.actions} actions, {args.particles} x {args.particles} cloth, {args.resolution} px")
    print("| agent | updates | train s | updates/s | eval s | final coverage (mean) | reach 0.9 | success | return |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    fmt = lambda x, spec: "-" if x is None else format(x, spec)
    for r in rows:
        print(f"| {r['agent']} | {r['updates']} | {fmt(r['train_s'], '.1f')} | {fmt(r['updates_per_s'], '.1f')} | "
              f"{r['evaluate_s']:.1f} | {r['final_coverage']:.3f} | {r['reach_90']}/{r['episodes']} | "
              f"{r['success_rate']:.0%} | {r['return_mean']:.2f} |")
    print(json.dumps({"collect": held, "rows": rows, "configs": {k: configs[k] for k in agents},
                      "oracle": oracle_config}, default=str))


if __name__ == "__main__":
    main()
