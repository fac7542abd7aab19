"""A world-model training run in pieces that fit a time-limited machine: what ``jarena train`` runs
(``train_and_evaluate`` with the agent's committed config for the arena and ``--set`` overrides), stopped after
``--chunks`` chunks per call with a checkpoint after every chunk, resumed from ``--run-dir`` by the next call
with the same arguments; the call that runs the last chunk evaluates on the eval episodes. Prints the history
rows and validations so far, with the seconds each call spent.

    python benchmarks/world_model_run.py dreamer "dmc|domain:walker,task:walk" --steps 100000 \\
        --set replay_ratio=512 --validations 4 --run-dir RUN --chunks 9      # repeat until it prints the eval
"""

from __future__ import annotations

import argparse
import json
import time

import jax

import jarena
import jarena_agents
from jarena.cli import parse_override, select_arg
from jarena.platform import enable_compilation_cache
from jarena.training import train_and_evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("agent")
    parser.add_argument("arena")
    parser.add_argument("--config", default="default", help="the agent's committed config for the arena")
    parser.add_argument("--steps", type=int, default=None, help="environment steps (default: the config's)")
    parser.add_argument("--set", action="append", type=parse_override, default=[], metavar="KEY=VALUE")
    parser.add_argument("--validations", type=int, default=10)
    parser.add_argument("--select", type=select_arg, default="best",
                        help="the policy the final evaluation runs: best, last or best:<validation column>")
    parser.add_argument("--chunks", type=int, default=None, help="chunks to run in this call (default: all)")
    parser.add_argument("--run-dir", required=True)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    cache = enable_compilation_cache()  # as the jarena command: a rerun loads its programs instead of compiling
    print(f"compilation cache: {cache or 'off'}", flush=True)

    start = time.perf_counter()
    arena = jarena.build_arena(args.arena)
    try:
        committed = jarena.retrieve_config(args.agent, arena, args.config)
    except FileNotFoundError:  # as `jarena train`: no committed default for this arena, the agent's own defaults
        if args.config != "default":
            raise
        committed = {}
    config = dict(committed, **dict(args.set))
    if args.steps is not None:
        config["total_steps"] = args.steps
    agent = jarena_agents.build_agent(args.agent, config)
    print(f"# {args.agent} on {args.arena}, {agent.settings.total_steps} steps, device "
          f"{jax.devices()[0].device_kind}, jax {jax.__version__}, config {args.config!r}, "
          f"overrides {dict(args.set)}", flush=True)
    result = train_and_evaluate(agent, arena, jax.random.key(args.seed), run_dir=args.run_dir, progress=False,
                                validations=args.validations, select=args.select, checkpoint_every=1,
                                stop_after_chunks=args.chunks, eval_videos=0)
    for row in result.history:
        print(json.dumps({k: round(v, 4) for k, v in row.items()}))
    for row in result.validations:
        print("validation", json.dumps({k: round(v, 3) for k, v in row.items()}))
    if result.evaluation is not None:
        print(result.evaluation.table())
    print(f"# this call: {time.perf_counter() - start:.1f} s", flush=True)


if __name__ == "__main__":
    main()
