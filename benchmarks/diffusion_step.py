"""Diffusion Policy's training update, in milliseconds, for each way of convolving (``jarena_agents.diffusion.
networks.convolve``: a matrix product over unfolded windows, or XLA's convolution operator), timed interleaved in
one process (``timing.time_interleaved``) on a dataset of demonstrations:

    jarena collect oracle_pusht "pusht|obs:image" --trajectories 200 --out demos
    python benchmarks/diffusion_step.py "pusht|obs:image" --set dataset=demos
    python benchmarks/diffusion_step.py "pusht|obs:keypoints" --set dataset=demos_kp --set batch_size=256

Prints one line per method and a JSON line: milliseconds per update of each, the ratio, and the minutes 100,000
updates would take at the faster rate.
"""

from __future__ import annotations

import argparse
import functools
import json

import jax
from timing import environment, time_interleaved

import jarena
import jarena_agents
from jarena.cli import parse_override
from jarena_agents.diffusion import networks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("arena")
    parser.add_argument("--set", action="append", type=parse_override, default=[], metavar="KEY=VALUE")
    parser.add_argument("--updates", type=int, default=50, help="updates per timed call")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--methods", default="matmul,xla,auto", help="comma-separated convolution methods")
    args = parser.parse_args()

    arena = jarena.build_arena(args.arena)
    try:
        committed = jarena.retrieve_config("diffusion", arena)
    except FileNotFoundError:  # as `jarena train`: no committed default for this arena, the agent's own defaults
        committed = {}
    config = dict(committed, **dict(args.set))
    agent = jarena_agents.build_agent("diffusion", config)
    start = agent.init_training(jax.random.key(0), arena)

    library = networks.convolve

    def maker(method):
        def run(train_state):  # Conv calls networks.convolve when the program is traced: the method is fixed there
            networks.convolve = functools.partial(library, method=method)
            try:
                return agent.train(train_state, arena, args.updates)[0]
            finally:
                networks.convolve = library
        return lambda: (run, start, args.updates)

    methods = args.methods.split(",")
    rates = time_interleaved({m: maker(m) for m in methods}, args.repeats, label="diffusion update ")
    ms = {m: 1e3 / r["per_s"] for m, r in rates.items()}
    fastest = min(ms.values())
    print(json.dumps({"arena": args.arena, "overrides": dict(args.set), "ms_per_update": ms,
                      "compile_s": {m: r["compile_s"] for m, r in rates.items()},
                      "ratio_first_to_each": {m: ms[methods[0]] / ms[m] for m in methods},
                      "minutes_per_100k_updates": fastest * 1e5 / 6e4, **environment()}))


if __name__ == "__main__":
    main()
