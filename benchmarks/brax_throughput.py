"""Env-steps per second of Brax's ant as a jarena arena (``brax|env:ant,backend:mjx``), against Brax's own loop.

Both sides step the same Brax env object code (``brax.envs.get_environment(env, backend=...)``) with the
same random actions, so the difference is what each loop adds around ``env.step``. Every variant runs
``--steps`` steps of a batch of B envs inside one jitted ``lax.scan``; compilation is timed apart
(``lower(...).compile()``), then one warm-up call, then ``--repeats`` timed calls interleaved across
variants (best shown). Actions: uniform in [-1, 1], one ``jax.random.fold_in(key, t)`` per step for the
whole batch, in every variant. Variants:

- ``auto``: ours, ``jarena.batch_step`` (step, then a fresh ``env.reset`` selected in where an episode
  ended: Brax's termination or the 1000-step time limit).
- ``auto-lazy`` (not run by default): ``auto`` with ``auto_reset:lazy`` (resets computed only in steps
  where some episode ended).
- ``auto-repeat``: ``auto`` with ``auto_reset:repeat``: each env restarts from its first initial state,
  Brax's own auto-reset semantics (the like-for-like comparison with ``brax``).
- ``step``: ours, ``jax.vmap(arena.step)``, no reset.
- ``brax``: Brax's training loop, ``brax.envs.training.wrap(env, episode_length=1000)`` (``VmapWrapper``,
  ``EpisodeWrapper``, ``AutoResetWrapper``), as Brax's PPO and SAC step it. Its auto-reset restores each
  env's *first* initial state (stored at reset) instead of drawing a new one, so it never calls
  ``env.reset`` while stepping; jarena's draws a new initial state per episode.
- ``brax-step``: ``jax.vmap(env.step)``, no wrappers, no reset.

Before timing, a short check counts episode ends in each auto-resetting loop (mean episode length), to
show that both reset at the same rate.

Usage::

    python benchmarks/brax_throughput.py                                   # GPU: B = 1024..32768
    python benchmarks/brax_throughput.py --batch-sizes 4 --steps 10 --repeats 1   # CPU smoke run
    python benchmarks/brax_throughput.py --env halfcheetah --backend generalized --out results/brax.md
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import importlib.metadata
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cartpole_throughput import cpu_model, fmt, parse_batches, write_report  # noqa: E402

#: Our auto-resetting variants and the ``auto_reset`` strategy each imposes (None: the arena's default).
AUTO_RESETS = {"auto": None, "auto-lazy": "lazy", "auto-repeat": "repeat"}
OURS = (*AUTO_RESETS, "step")
PEERS = ("brax", "brax-step")
ALL_VARIANTS = OURS + PEERS
DEFAULT_VARIANTS = ("auto", "auto-repeat", "step", "brax", "brax-step")
EPISODE_LENGTH = 1000  # Brax's default episode_length; jarena's brax arenas default to the same time limit


# ---------------------------------------------------------------------------------------------- loops
# Each factory returns (init, body): ``init(key) -> carry`` resets B envs (not timed);
# ``body(carry, t) -> (carry, done)`` is one step of the loop, ``done`` a (B,) bool of episode ends.


def _actions(key: jax.Array, t: jax.Array, batch: int, size: int) -> jax.Array:
    return jax.random.uniform(jax.random.fold_in(key, t), (batch, size), minval=-1.0, maxval=1.0)


def ours(variant: str, batch: int, env_name: str, backend: str) -> tuple[Callable, Callable]:
    arena = jarena.build_arena(f"brax|env:{env_name},backend:{backend},time_limit:{EPISODE_LENGTH}")
    if AUTO_RESETS.get(variant) is not None:
        arena = dataclasses.replace(arena, auto_reset=AUTO_RESETS[variant])
    params = arena.default_params()
    size = arena.action_spec.shape[0]
    step = jax.vmap(arena.step, in_axes=(0, 0, None))

    def init(key):
        key_reset, key_loop = jax.random.split(key)
        states, _ = jarena.batch_reset(arena, key_reset, batch, params)
        return states, key_loop

    if variant in AUTO_RESETS:
        def body(carry, t):
            states, key = carry
            states, info = jarena.batch_step(arena, states, _actions(key, t, batch, size), params)
            return (states, key), info.done
    elif variant == "step":
        def body(carry, t):
            states, key = carry
            states, info = step(states, _actions(key, t, batch, size), params)
            return (states, key), info.done
    else:
        raise ValueError(f"unknown variant of ours {variant!r}; choose from {OURS}")
    return init, body


def brax_loop(variant: str, batch: int, env_name: str, backend: str) -> tuple[Callable, Callable]:
    from brax import envs
    from brax.envs.wrappers import training

    env = envs.get_environment(env_name, backend=backend)
    size = env.action_size

    def raw_keys(key):  # Brax's wrappers take raw uint32 keys (EpisodeWrapper reads rng.shape[:-1])
        return jax.random.key_data(jax.random.split(key, batch))

    if variant == "brax":
        wrapped = training.wrap(env, episode_length=EPISODE_LENGTH)

        def init(key):
            key_reset, key_loop = jax.random.split(key)
            return wrapped.reset(raw_keys(key_reset)), key_loop

        def body(carry, t):
            state, key = carry
            state = wrapped.step(state, _actions(key, t, batch, size))
            return (state, key), state.done > 0
    elif variant == "brax-step":
        step = jax.vmap(env.step)

        def init(key):
            key_reset, key_loop = jax.random.split(key)
            return jax.vmap(env.reset)(raw_keys(key_reset)), key_loop

        def body(carry, t):
            state, key = carry
            state = step(state, _actions(key, t, batch, size))
            return (state, key), state.done > 0
    else:
        raise ValueError(f"unknown brax variant {variant!r}; choose from {PEERS}")
    return init, body


def make_loop(variant: str, batch: int, env_name: str, backend: str):
    factory = ours if variant in OURS else brax_loop
    return factory(variant, batch, env_name, backend)


# ---------------------------------------------------------------------------------------------- timing


def compile_variant(variant: str, batch: int, steps: int, args, seed: int = 0) -> dict:
    """Resets ``batch`` envs and compiles ``steps`` steps of the loop; returns the program and its input."""
    init, body = make_loop(variant, batch, args.env, args.backend)

    def run(carry):
        carry, _ = jax.lax.scan(lambda c, t: (body(c, t)[0], None), carry, jnp.arange(steps, dtype=jnp.int32))
        return carry

    carry = jax.block_until_ready(jax.jit(init)(jax.random.key(seed)))
    t0 = time.perf_counter()
    compiled = jax.jit(run).lower(carry).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(carry))  # warm-up
    return {"compiled": compiled, "carry": carry, "compile_s": compile_s}


def time_batch(variants: list[str], batch: int, args) -> list[dict]:
    """Times every variant at one batch size, timed calls interleaved across variants; one row each."""
    progs = {v: compile_variant(v, batch, args.steps, args) for v in variants}
    times = {v: [] for v in variants}
    for _ in range(args.repeats):
        for v, p in progs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(p["compiled"](p["carry"]))
            times[v].append(time.perf_counter() - t0)
    rows = []
    for v in variants:
        best, median = min(times[v]), statistics.median(times[v])
        rows.append({"variant": v, "batch": batch, "steps": args.steps, "compile_s": progs[v]["compile_s"],
                     "best_s": best, "median_s": median, "steps_per_s": batch * args.steps / best,
                     "steps_per_s_median": batch * args.steps / median})
    return rows


def mean_episode_length(variant: str, args, seed: int = 1) -> float | None:
    """Env-steps per finished episode over ``--check-steps`` steps of ``--check-batch`` envs (``None``: none ended)."""
    batch, steps = args.check_batch, args.check_steps
    init, body = make_loop(variant, batch, args.env, args.backend)

    def run(key):
        def count_body(c, t):
            carry, n = c
            carry, done = body(carry, t)
            return (carry, n + jnp.sum(done, dtype=jnp.int32)), None
        (_, n), _ = jax.lax.scan(count_body, (init(key), jnp.zeros((), jnp.int32)), jnp.arange(steps))
        return n

    n = int(jax.jit(run)(jax.random.key(seed)))
    return batch * steps / n if n else None


# ---------------------------------------------------------------------------------------------- report


def environment() -> dict:
    dev = jax.devices()[0]
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "backend": jax.default_backend(), "device": dev.device_kind, "num_devices": jax.device_count(),
            "cpu": cpu_model(), "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "jax": jax.__version__, "jaxlib": importlib.metadata.version("jaxlib"),
            "brax": importlib.metadata.version("brax"), "mujoco": importlib.metadata.version("mujoco"),
            "jarena_path": os.path.dirname(os.path.abspath(jarena.__file__)),
            "command": " ".join(["python"] + sys.argv)}


def _length(x: float | None) -> str:
    return "(no episode ended)" if x is None else f"{x:.1f}"


def markdown(env: dict, rows: list[dict], variants: list[str], lengths: dict, args) -> str:
    by = {(r["variant"], r["batch"]): r for r in rows}

    def ratio(a, b, batch):
        ra, rb = by.get((a, batch)), by.get((b, batch))
        return None if ra is None or rb is None else ra["steps_per_s"] / rb["steps_per_s"]

    pairs = [(a, b) for a, b in (("auto", "brax"), ("auto-lazy", "brax"), ("auto-repeat", "brax"),
                                              ("step", "brax-step"))
             if a in variants and b in variants]
    lines = [f"- env: brax `{args.env}` on backend `{args.backend}`, episode length {EPISODE_LENGTH}",
             f"- date: {env['date']}", f"- device: {env['device']} (backend {env['backend']}, "
             f"{env['num_devices']} device(s)); host CPU: {env['cpu']}, {env['cpu_count']} cores",
             f"- python {env['python']}, jax {env['jax']}, jaxlib {env['jaxlib']}, brax {env['brax']}, "
             f"mujoco {env['mujoco']}",
             f"- steps per call: {args.steps}, repeats: {args.repeats} (best shown)",
             f"- command: `{env['command']}`", ""]
    if lengths:
        lines += [f"Mean episode length (env-steps per finished episode, B={args.check_batch}, "
                  f"{args.check_steps} steps): " + ", ".join(f"{v} {_length(x)}" for v, x in lengths.items()), ""]
    head = (["batch"] + [f"{v} steps/s" for v in variants] + [f"{a} / {b}" for a, b in pairs]
            + ["compile s (" + ", ".join(variants) + ")"])
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for b in sorted({r["batch"] for r in rows}):
        cells = [str(b)] + [fmt(by[(v, b)]["steps_per_s"]) if (v, b) in by else "-" for v in variants]
        cells += [fmt(ratio(x, y, b)) for x, y in pairs]
        cells.append(", ".join(f"{by[(v, b)]['compile_s']:.1f}" if (v, b) in by else "-" for v in variants))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------- CLI


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog="Defaults depend on the backend: "
                                "on accelerators batches 2^10..2^15 and 200 steps, on CPU batch 4 and 10 steps "
                                "(a smoke run).", formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--env", default="ant", help="a Brax env of the brax builder (ant, halfcheetah, humanoid, ...)")
    p.add_argument("--backend", default="mjx", help="Brax physics backend: mjx, generalized, positional, spring")
    p.add_argument("--batch-sizes", type=parse_batches, default=None,
                   help="comma-separated batch sizes; 'B^i..B^j' expands to powers (e.g. 2^10..2^15)")
    p.add_argument("--steps", type=int, default=None, help="steps per timed call (one lax.scan)")
    p.add_argument("--repeats", type=int, default=None,
                   help="timed calls per variant after one warm-up, interleaved across variants; best shown "
                        "(default 5 on accelerators, 1 on CPU)")
    p.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                   help=f"comma-separated subset of {','.join(ALL_VARIANTS)}")
    p.add_argument("--check-batch", type=int, default=None,
                   help="batch of the episode-length check (default 4096 on accelerators, 4 on CPU)")
    p.add_argument("--check-steps", type=int, default=None,
                   help="steps of the episode-length check (default 1000 on accelerators, 10 on CPU)")
    p.add_argument("--no-check", action="store_true", help="skip the episode-length check before timing")
    p.add_argument("--out", default=None, help="write the table to this .md file and the raw numbers beside it "
                   "as .json (or the other way round when it ends in .json)")
    args = p.parse_args(argv)
    gpu = jax.default_backend() != "cpu"
    args.batch_sizes = args.batch_sizes or ([2**i for i in range(10, 16)] if gpu else [4])
    args.steps = args.steps or (200 if gpu else 10)
    args.repeats = args.repeats or (5 if gpu else 1)
    args.check_batch = args.check_batch or (4096 if gpu else 4)
    args.check_steps = args.check_steps or (1000 if gpu else 10)
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    bad = [v for v in variants if v not in ALL_VARIANTS]
    if bad:
        p.error(f"unknown variant(s) {bad}; choose from {list(ALL_VARIANTS)}")
    args.variant_list = variants
    return args


def main(argv=None) -> int:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    from jarena.platform import avoid_cpu_eigen_deadlock
    avoid_cpu_eigen_deadlock()  # on 2-core CPU hosts, before JAX starts its CPU backend
    args = parse_args(argv)
    env = environment()
    print(f"# brax {args.env} ({args.backend}) on {env['device']} ({env['backend']}), jax {env['jax']}, "
          f"brax {env['brax']}", flush=True)
    lengths = {}
    if not args.no_check:
        for v in args.variant_list:
            if v in (*AUTO_RESETS, "brax"):
                lengths[v] = mean_episode_length(v, args)
        if lengths:
            print("mean episode length: " + ", ".join(f"{v} {_length(x)}" for v, x in lengths.items()), flush=True)
    rows = []
    for b in args.batch_sizes:
        for r in time_batch(args.variant_list, b, args):
            rows.append(r)
            print(f"B={b:>7} {r['variant']:>10}: {r['steps_per_s']:.3e} steps/s (median "
                  f"{r['steps_per_s_median']:.3e}), {r['best_s'] * 1e3:.1f} ms/call, compile {r['compile_s']:.1f} s",
                  flush=True)
    table = markdown(env, rows, args.variant_list, lengths, args)
    print()
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": dict(vars(args)), "episode_length": lengths,
                                       "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
