"""Where a Dreamer run's time goes: milliseconds per update (one collection step of every arena plus the update's
gradient steps), compiled chunks timed after their first call, for the agent's committed config with ``--set``
overrides. Run it once per variant in a fresh process (XLA flags are read at start-up), e.g. on a GPU:

    A="dmc|domain:walker,task:walk"
    python benchmarks/dreamer_step.py "$A"                                # the default config
    python benchmarks/dreamer_step.py "$A" --set learning_starts=100000000  # collection alone
    python benchmarks/dreamer_step.py "$A" --set num_arenas=64              # more arenas per update
    XLA_FLAGS=--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL \\
        python benchmarks/dreamer_step.py "$A"

Prints one JSON line: the variant, milliseconds per update and per decision, gradient steps per update, and the
minutes of training that 500k environment steps would take at that rate (decisions times the config's and the
arena's action repeat); or, when the program fails to compile or run, the variant and the error's first line.
``--compile-only`` stops once the filling call has run and the timed chunk's program has compiled (with
``JAX_COMPILATION_CACHE_DIR`` set, a later timed run of the same variant then loads both). ``--patch flat-norm``
swaps optax's ``clip_by_global_norm`` for the world model's ``clip_by_flat_global_norm`` (one reduction over all
leaves), which the world model and Dreamer now use themselves (optax's per-leaf sums stopped XLA's GPU compiler at
batches of 32 or more).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import jax
import optax

import jarena
import jarena_agents
from jarena.cli import parse_override
from jarena_agents.world_model import model as wm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("arena")
    parser.add_argument("--agent", default="dreamer")
    parser.add_argument("--config", default="default")
    parser.add_argument("--set", action="append", type=parse_override, default=[], metavar="KEY=VALUE")
    parser.add_argument("--updates", type=int, default=20, help="updates per timed chunk")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--compile-only", action="store_true", help="stop after the first compiled call")
    parser.add_argument("--patch", choices=["flat-norm"], default=None)
    parser.add_argument("--seeds", type=int, default=1,
                        help="train this many seeds at once, vmapped, as `jarena train --seeds` does (the times are "
                             "then for all seeds together)")
    args = parser.parse_args()
    if args.patch == "flat-norm":
        optax.clip_by_global_norm = wm.clip_by_flat_global_norm  # the library's clip since; kept for old variants

    arena = jarena.build_arena(args.arena)
    overrides = dict(args.set)
    base = jarena.retrieve_config(args.agent, arena, args.config)
    # learning starts once every arena holds one sequence (unless overridden), so the timed chunks train
    config = {**base, "learning_starts": 0, **overrides}
    agent = jarena_agents.build_agent(args.agent, config)
    cfg = agent.settings
    warmup = -(-(cfg.sequence_length + 1) // cfg.rollout_length)  # updates until every arena holds a sequence
    if args.seeds == 1:
        state = agent.init_training(jax.random.key(0), arena)
        fill = jax.jit(lambda ts: agent.train(ts, arena, warmup))
        chunk = jax.jit(lambda ts: agent.train(ts, arena, args.updates))
    else:
        keys = jax.random.split(jax.random.key(0), args.seeds)
        state = jax.jit(jax.vmap(lambda key: agent.init_training(key, arena)))(keys)
        fill = jax.jit(jax.vmap(lambda ts: agent.train(ts, arena, warmup)))
        chunk = jax.jit(jax.vmap(lambda ts: agent.train(ts, arena, args.updates)))
    variant = {"arena": args.arena, "overrides": overrides, "patch": args.patch, "seeds": args.seeds,
               "xla_flags": os.environ.get("XLA_FLAGS", ""), "device": jax.devices()[0].device_kind,
               "jax": jax.__version__}
    start = time.perf_counter()
    try:
        state, _ = fill(state)
        jax.block_until_ready(state)
    except Exception as error:  # a compiler or runtime failure is this variant's result
        print(json.dumps({**variant, "error": str(error).splitlines()[0][:300],
                          "seconds": round(time.perf_counter() - start, 1)}), flush=True)
        return
    fill_s = time.perf_counter() - start
    print(f"filled the buffer (and compiled) in {fill_s:.1f} s", file=sys.stderr, flush=True)  # a call cut short
    if args.compile_only:  # the timed chunk's program too, so that a later run finds both in the compilation cache
        chunk.lower(state).compile()
        print(json.dumps({**variant, "compiled": True, "fill_and_compile_s": round(fill_s, 1),
                          "both_compiled_s": round(time.perf_counter() - start, 1)}), flush=True)
        return
    start = time.perf_counter()
    state, _ = chunk(state)
    jax.block_until_ready(state)
    first_s = time.perf_counter() - start
    print(f"first chunk of {args.updates} updates (compiled) in {first_s:.1f} s", file=sys.stderr, flush=True)
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        state, metrics = chunk(state)
        jax.block_until_ready(state)
        times.append(time.perf_counter() - start)
    per_update = statistics.median(times) / args.updates
    repeat = int(getattr(arena.tool, "substeps", 1) or 1)  # an arena that repeats actions itself
    decisions = getattr(cfg, "decisions_per_update", cfg.steps_per_update)
    env_steps = cfg.steps_per_update * repeat  # per update: the config's action_repeat and the arena's
    trained = bool(float(jax.device_get(metrics["model_loss"]).mean()) != 0.0) if "model_loss" in metrics else None
    print(json.dumps({
        **variant, "num_arenas": cfg.num_arenas, "gradient_steps_per_update": cfg.gradient_steps, "trained": trained,
        "ms_per_update": round(per_update * 1e3, 2), "ms_per_decision": round(per_update * 1e3 / decisions, 3),
        "minutes_for_500k_env_steps": round(500_000 / env_steps * per_update / 60, 1),
        "fill_and_compile_s": round(fill_s, 1), "first_chunk_s": round(first_s, 1)}), flush=True)


if __name__ == "__main__":
    main()
