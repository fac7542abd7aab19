"""Transporter Networks on a Raven task (``--task``, default block-insertion): oracle demonstrations, training,
and success over the 100 eval episodes, with the wall time of each part. Made for a GPU (the paper's network and
40,000 updates).

    python benchmarks/transporter_raven.py --demos 100 --steps 40000 --run-dir runs/transporter

1. ``jarena.collect``: ``--demos`` episodes of ``oracle_raven`` (training episodes) into a dataset;
2. ``train_and_evaluate``: ``transporter`` for ``--steps`` gradient updates (default config: the paper's), then the
   final policy on the 100 eval episodes (no validation, unless ``--validations``: then the policy of ``--select``,
   by default the best validation success, as Transporter's paper reports the best validated snapshot).

Prints the oracle's success over the collected episodes, the training loss at the start and the end, the success
rate and mean return over the eval episodes, and the wall times (compilation included; the training's also without
its first chunk, which compiles). ``--set KEY=VALUE`` overrides a config key (e.g. ``--set batch_size=8``).
"""

from __future__ import annotations

import argparse
import json
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
from jarena.training import train_and_evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", default="block-insertion", help="the Raven task (raven|task:<name>)")
    parser.add_argument("--demos", type=int, default=100, help="oracle episodes to learn from (paper: 1 to 1000)")
    parser.add_argument("--steps", type=int, default=40_000, help="gradient updates")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--validations", type=int, default=0, help="validate this many times during training")
    parser.add_argument("--select", default="best:success_rate",
                        help="with --validations, the policy evaluated (the paper reports the best validated)")
    parser.add_argument("--devices", default=None, help="train data-parallel on N devices, or 'all'")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key")
    parser.add_argument("--run-dir", default=None, help="keep the dataset, logs and results here")
    args = parser.parse_args()
    cache = enable_compilation_cache()  # as the jarena command: a rerun loads its programs instead of compiling
    print(f"compilation cache: {cache or 'off'}", flush=True)
    devices = args.devices if args.devices in (None, "all") else int(args.devices)
    overrides = {k: yaml.safe_load(v) for k, v in (item.split("=", 1) for item in args.set)}
    print(f"devices: {jax.devices()}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.run_dir or tmp)
        root.mkdir(parents=True, exist_ok=True)
        arena = jarena.build_arena(f"raven|task:{args.task}")
        demos = root / f"oracle_{args.demos}"
        start = time.perf_counter()
        with TrajectoryDataset(demos, "w", **configs_for(arena)) as dataset:
            jarena.collect(jarena_agents.build_agent("oracle_raven"), arena, dataset, args.demos,
                           key=jax.random.key(args.seed + 1_000), progress=False)
            rewards = [float(np.sum(dataset.get_trajectory(i)["reward"])) for i in range(dataset.num_trajectories())]
            steps = dataset.num_steps()
        collect_s = time.perf_counter() - start
        print(f"collected {args.demos} oracle episodes ({steps} actions) in {collect_s:.1f} s; oracle success "
              f"{np.mean(np.asarray(rewards) > 0.99):.0%}", flush=True)

        agent = jarena_agents.build_agent("transporter", dict(overrides, dataset=str(demos), total_steps=args.steps))
        start = time.perf_counter()
        schedule = (dict(validations=args.validations, select=args.select) if args.validations
                    else dict(validate_every=0))
        result = train_and_evaluate(agent, arena, jax.random.key(args.seed), run_dir=root / "run", progress=False,
                                    eval_videos=0, devices=devices, **schedule)
        total_s = time.perf_counter() - start
        history = result.history
        train_s = history[-1]["seconds"]
        first = history[0]
        steady = (history[-1]["update"] - first["update"]) / max(train_s - first["seconds"], 1e-9)
        summary = result.evaluation.summary()
        print(f"trained {args.steps} updates in {train_s:.1f} s ({steady:.1f} updates/s after the first chunk, which "
              f"took {first['seconds']:.1f} s with compilation); loss {first['loss']:.3f} in the first chunk, "
              f"{history[-1]['loss']:.3f} in the last", flush=True)
        print(f"evaluated {int(summary['episodes'])} eval episodes in {total_s - train_s:.1f} s (validations and "
              f"compilation included): success {summary['success_rate']:.0%}, return {summary['return_mean']:.3f}",
              flush=True)
        print(json.dumps({"demos": args.demos, "steps": args.steps, "config": agent.config, "collect_s": collect_s,
                          "train_s": train_s, "updates_per_s": steady, "evaluate_s": total_s - train_s,
                          "selected": result.evaluation.selected,
                          **{k: summary[k] for k in ("success_rate", "return_mean", "episodes")}}, default=str))


if __name__ == "__main__":
    main()
