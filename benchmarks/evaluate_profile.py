"""Where ``evaluate``'s time goes on several devices, against a ``perform_parallel`` rollout of the same steps.

For each device count (weak scaling: ``--arenas`` per device) it times, best of ``--repeats``:

- ``rollout``: a random agent's ``perform_parallel`` (``record=False``), ``--steps`` steps of every arena;
- ``evaluate``: the whole call (one episode per arena capped at ``--steps``, results fetched to the host; its loop
  ends when every episode has, so it may run fewer steps than the rollout);
- ``loop``: the compiled episode loop alone (inputs already on the devices, outputs left there);
- ``loop, block K``: the same with the "is every episode done?" check after blocks of K steps, for each K of
  ``--blocks`` (the library picks the block with ``steps_per_check``);
- ``stages``: one ``evaluate`` call cut at its stages, each timed on fresh outputs (best total of ``--repeats``):
  ``prepare`` (argument checks, the agent's state, the inputs sent to the devices), ``loop`` (the compiled call,
  waited for), ``fetch`` (the per-episode results copied to the host) and ``result`` (the host arrays made an
  ``EvalResult``).

    python benchmarks/evaluate_profile.py --arena "classic|domain:cartpole" --arenas 1048576 --devices 1,2,4

Prints one line per measurement and a JSON summary (with the machine) at the end.
"""

from __future__ import annotations

import argparse
import importlib
import json
import time

import jax
import numpy as np
from timing import environment

import jarena
import jarena_agents
from jarena import distributed

evaluate_module = importlib.import_module("jarena.runners.evaluate")  # the module, not the function


def best_of(fn, repeats: int) -> float:
    """Seconds of the fastest of ``repeats`` calls of ``fn`` after one warm-up call."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def loop_call(agent, arena, num: int, steps: int, devices: int):
    """A no-argument function running :func:`evaluate`'s compiled loop on device inputs, returning its outputs."""
    mesh = distributed.mesh(devices)
    key = jax.random.key(0)
    agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, num)
    params = arena.default_params()
    fn = evaluate_module._compiled_episodes(agent, arena, num, steps, None, 0, mesh if devices > 1 else None,
                                            jax.random.key_impl(key))
    args = (np.asarray(jax.random.key_data(key)), agent_state, params, np.arange(num, dtype=np.int32))
    with distributed.tracing_on(mesh):
        args = jax.device_put(args, distributed.replicated(mesh)) if devices > 1 else jax.device_put(args)

        def run():
            with distributed.tracing_on(mesh):
                return jax.block_until_ready(fn(*args))
        return run


def evaluate_stages(agent, arena, num: int, steps: int, devices: int, repeats: int) -> dict:
    """Seconds of each stage of one :func:`jarena.evaluate` call (the call with the fastest total of ``repeats``
    after a warm-up): ``prepare``, ``loop``, ``fetch`` and ``result`` (see the module docstring)."""
    marks = {}
    compiled, fetch = evaluate_module._compiled_episodes, distributed.fetch

    def timed_compiled(*args, **kwargs):
        fn = compiled(*args, **kwargs)

        def call(*inputs):
            marks["loop_start"] = time.perf_counter()
            out = jax.block_until_ready(fn(*inputs))
            marks["loop_end"] = time.perf_counter()
            return out
        return call

    def timed_fetch(tree, name="fetch"):
        start = time.perf_counter()
        out = fetch(tree, name)
        if name.endswith("episodes"):  # the per-episode results (not the agent state's copy in prepare)
            marks["fetch"] = (start, time.perf_counter())
        return out

    evaluate_module._compiled_episodes, distributed.fetch = timed_compiled, timed_fetch
    try:
        rows = []
        episodes = np.arange(num)
        for _ in range(repeats + 1):
            t0 = time.perf_counter()
            jarena.evaluate(agent, arena, jax.random.key(1), episodes=episodes, max_steps=steps, devices=devices)
            t1 = time.perf_counter()
            rows.append({"prepare": marks["loop_start"] - t0, "loop": marks["loop_end"] - marks["loop_start"],
                         "fetch": marks["fetch"][1] - marks["fetch"][0], "result": t1 - marks["fetch"][1],
                         "total": t1 - t0})
    finally:
        evaluate_module._compiled_episodes, distributed.fetch = compiled, fetch
    return min(rows[1:], key=lambda row: row["total"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arena", default="classic|domain:cartpole")
    parser.add_argument("--arenas", type=int, default=1 << 20, help="arenas per device")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--devices", default="1,all")
    parser.add_argument("--blocks", default="1,8,25", help="steps between 'all done?' checks to try")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    arena = jarena.build_arena(args.arena)
    agent = jarena_agents.build_agent("random")
    counts = sorted({int(c) if c != "all" else len(jax.local_devices()) for c in args.devices.split(",")})
    blocks = [int(b) for b in args.blocks.split(",")]
    library_block = evaluate_module.steps_per_check
    results = {}
    for d in counts:
        n = args.arenas * d
        row = {"devices": d, "arenas": n, "library_block": library_block(args.steps, d)}
        work = n * args.steps
        row["rollout_s"] = best_of(lambda: jax.block_until_ready(jarena.perform_parallel(
            agent, arena, jax.random.key(1), n, args.steps, record=False, devices=d).info.reward), args.repeats)
        row["evaluate_s"] = best_of(lambda: jarena.evaluate(agent, arena, jax.random.key(1), episodes=np.arange(n),
                                                            max_steps=args.steps, devices=d), args.repeats)
        stages = evaluate_stages(agent, arena, n, args.steps, d, args.repeats)
        row.update({f"stage_{k}_s": v for k, v in stages.items() if k != "total"})
        for block in blocks:
            evaluate_module.steps_per_check = lambda max_steps, devices, b=block: b
            evaluate_module._compiled_episodes.cache_clear()
            run = loop_call(agent, arena, n, args.steps, d)
            row[f"loop_block{block}_s"] = best_of(run, args.repeats)
        evaluate_module.steps_per_check = library_block
        evaluate_module._compiled_episodes.cache_clear()
        results[d] = row
        print(f"{d} device(s) {n} arenas: rollout {work / row['rollout_s']:.3g} steps/s; " + ", ".join(
            f"{k[:-2]} {v * 1e3:.1f} ms" for k, v in row.items() if k.endswith("_s")), flush=True)
    base = results[counts[0]]
    print("weak scaling (work per second against the first device count's):")
    for d, row in results.items():
        print(f"{d} device(s): " + ", ".join(f"{k[:-2]} {base[k] * d / counts[0] / v:.2f}x" for k, v in row.items()
                                             if k.endswith("_s") and not k.startswith("stage_")))
    print(json.dumps({"results": results, "environment": environment(arena=args.arena,
                                                                      devices=len(jax.local_devices()))}, indent=2))


if __name__ == "__main__":
    main()
