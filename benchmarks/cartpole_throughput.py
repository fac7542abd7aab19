"""Env-steps per second of classic cartpole with random actions, against gymnax's CartPole-v1.

Every variant runs ``--steps`` steps of a batch of B arenas inside one jitted ``lax.scan``; the clock
(``time.perf_counter`` around the compiled call, after a warm-up call, with ``jax.block_until_ready``)
never sees compilation, which is timed apart (``lower(...).compile()``); the timed calls of all variants
are interleaved, so that a change in the machine's load weighs on every variant alike. Variants:

- ``step``: ours, ``jax.vmap(arena.step)`` with no reset; the batch's actions come from one
  ``jax.random.fold_in(key, t)`` per step.
- ``auto``: ours, ``jarena.batch_step`` (step + auto-reset); actions as in ``step``.
- ``auto-split``: ours, ``jarena.batch_step`` in the loop gymnax users write: the carried key is split
  every step and every arena draws its action from its own key (``arena.sample_action``).
- ``gymnax``: gymnax's ``CartPole-v1`` in that same loop: split the key every step, one key per
  environment for the action (``action_space.sample``) and one for ``env.step`` (which auto-resets).
- ``gymnax-fold`` (not run by default): gymnax with the batch's actions from ``fold_in(key, t)``; its
  ``env.step`` still needs one key per environment and step.

Both libraries draw random actions every step and auto-reset finished episodes (``step`` aside); a
short check before timing counts episode ends in each auto-resetting loop, so the mean episode
lengths show that both do the same work.

Usage::

    python benchmarks/cartpole_throughput.py                       # defaults depend on the backend
    python benchmarks/cartpole_throughput.py --batch-sizes 1,1024,65536 --steps 200 --out results.md
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
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

ARENA = "classic|domain:cartpole,task:balance"
OURS = ("step", "auto", "auto-split")
PEERS = ("gymnax", "gymnax-fold")
ALL_VARIANTS = OURS + PEERS
DEFAULT_VARIANTS = ("step", "auto", "auto-split", "gymnax")


# ---------------------------------------------------------------------------------------------- loops
# Each factory returns (init, body): ``init(key) -> carry`` resets B arenas (not timed);
# ``body(carry, t) -> (carry, done)`` is one step of the loop, ``done`` a (B,) bool of episode ends.


def ours(variant: str, batch: int) -> tuple[Callable, Callable]:
    arena = jarena.build_arena(ARENA)
    params = arena.default_params()
    spec = arena.action_spec  # Discrete(2)
    step = jax.vmap(arena.step, in_axes=(0, 0, None))

    def init(key):
        key_reset, key_loop = jax.random.split(key)
        states, _ = jarena.batch_reset(arena, key_reset, batch, params)
        return states, key_loop

    def batch_actions(key, t):
        return jax.random.randint(jax.random.fold_in(key, t), (batch,), 0, spec.n, dtype=spec.dtype)

    if variant == "step":
        def body(carry, t):
            states, key = carry
            states, info = step(states, batch_actions(key, t), params)
            return (states, key), info.done
    elif variant == "auto":
        def body(carry, t):
            states, key = carry
            states, info = jarena.batch_step(arena, states, batch_actions(key, t), params)
            return (states, key), info.done
    elif variant == "auto-split":
        def body(carry, t):
            states, key = carry
            key, key_act = jax.random.split(key)
            actions = jax.vmap(arena.sample_action)(jax.random.split(key_act, batch))
            states, info = jarena.batch_step(arena, states, actions, params)
            return (states, key), info.done
    else:
        raise ValueError(f"unknown variant of ours {variant!r}; choose from {OURS}")
    return init, body


def gymnax_loop(variant: str, batch: int) -> tuple[Callable, Callable]:
    import gymnax

    env, params = gymnax.make("CartPole-v1")
    space = env.action_space(params)
    step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def init(key):
        key_reset, key_loop = jax.random.split(key)
        _, states = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key_reset, batch), params)
        return states, key_loop

    def done_of(out):
        # gymnax >= 1.0 returns (obs, state, reward, terminated, truncated, info); older: a 5-tuple with done.
        return (out[3] | out[4]) if len(out) == 6 else out[3]

    if variant == "gymnax":
        def body(carry, t):
            states, key = carry
            key, key_act, key_step = jax.random.split(key, 3)
            actions = jax.vmap(space.sample)(jax.random.split(key_act, batch))
            out = step(jax.random.split(key_step, batch), states, actions, params)
            return (out[1], key), done_of(out)
    elif variant == "gymnax-fold":
        def body(carry, t):
            states, key = carry
            actions = jax.random.randint(jax.random.fold_in(key, t), (batch,), 0, space.n)
            key_step = jax.random.fold_in(jax.random.fold_in(key, t), 1)
            out = step(jax.random.split(key_step, batch), states, actions, params)
            return (out[1], key), done_of(out)
    else:
        raise ValueError(f"unknown gymnax variant {variant!r}; choose from {PEERS}")
    return init, body


def make_loop(variant: str, batch: int):
    return ours(variant, batch) if variant in OURS else gymnax_loop(variant, batch)


# ---------------------------------------------------------------------------------------------- timing


def compile_variant(variant: str, batch: int, steps: int, unroll: int, seed: int = 0,
                    dump_hlo: str | None = None) -> dict:
    """Resets ``batch`` arenas and compiles ``steps`` steps of the loop; returns the program and its input.

    With ``dump_hlo`` (a folder), writes the optimised HLO of the compiled program there.
    """
    init, body = make_loop(variant, batch)

    def run(carry):
        def timed_body(c, t):
            c, _ = body(c, t)
            return c, None
        carry, _ = jax.lax.scan(timed_body, carry, jnp.arange(steps, dtype=jnp.int32), unroll=unroll)
        return carry

    carry = jax.block_until_ready(jax.jit(init)(jax.random.key(seed)))
    t0 = time.perf_counter()
    compiled = jax.jit(run).lower(carry).compile()
    compile_s = time.perf_counter() - t0
    if dump_hlo:
        os.makedirs(dump_hlo, exist_ok=True)
        with open(os.path.join(dump_hlo, f"{variant}_B{batch}.hlo.txt"), "w") as f:
            f.write(compiled.as_text())
    jax.block_until_ready(compiled(carry))  # warm-up
    return {"compiled": compiled, "carry": carry, "compile_s": compile_s}


def time_batch(variants: list[str], batch: int, steps: int, repeats: int, unroll: int = 1,
               dump_hlo: str | None = None) -> list[dict]:
    """Times every variant at one batch size; returns one row per variant (seconds and steps per second).

    The timed calls are interleaved (each repeat runs every variant once), so that a change in the
    machine's load during the run weighs on all variants alike and the ratios stay fair.
    """
    progs = {v: compile_variant(v, batch, steps, unroll, dump_hlo=dump_hlo) for v in variants}
    times = {v: [] for v in variants}
    for _ in range(repeats):
        for v, p in progs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(p["compiled"](p["carry"]))
            times[v].append(time.perf_counter() - t0)
    rows = []
    for v in variants:
        best, median = min(times[v]), statistics.median(times[v])
        rows.append({"variant": v, "batch": batch, "steps": steps, "compile_s": progs[v]["compile_s"],
                     "best_s": best, "median_s": median, "steps_per_s": batch * steps / best,
                     "steps_per_s_median": batch * steps / median})
    return rows


def time_variant(variant: str, batch: int, steps: int, repeats: int, unroll: int = 1,
                 dump_hlo: str | None = None) -> dict:
    """Times one variant at one batch size (see :func:`time_batch`)."""
    return time_batch([variant], batch, steps, repeats, unroll, dump_hlo)[0]


def mean_episode_length(variant: str, batch: int = 4096, steps: int = 300, seed: int = 1) -> float:
    """Env-steps per finished episode over a short run: both libraries must reset at the same rate."""
    init, body = make_loop(variant, batch)

    def run(key):
        def count_body(c, t):
            carry, n = c
            carry, done = body(carry, t)
            return (carry, n + jnp.sum(done, dtype=jnp.int32)), None
        (_, n), _ = jax.lax.scan(count_body, (init(key), jnp.zeros((), jnp.int32)), jnp.arange(steps))
        return n

    n = int(jax.jit(run)(jax.random.key(seed)))
    return batch * steps / max(n, 1)


# ---------------------------------------------------------------------------------------------- report


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment() -> dict:
    dev = jax.devices()[0]
    try:
        gymnax_version = importlib.metadata.version("gymnax")
    except importlib.metadata.PackageNotFoundError:
        gymnax_version = None
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "backend": jax.default_backend(), "device": dev.device_kind, "num_devices": jax.device_count(),
            "cpu": cpu_model(), "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "jax": jax.__version__, "jaxlib": importlib.metadata.version("jaxlib"), "gymnax": gymnax_version,
            "jarena_path": os.path.dirname(os.path.abspath(jarena.__file__)),
            "command": " ".join(["python"] + sys.argv)}


def fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.3g}"


def ratio(a: dict | None, b: dict | None) -> float | None:
    return None if a is None or b is None else a["steps_per_s"] / b["steps_per_s"]


def markdown(env: dict, rows: list[dict], variants: list[str], lengths: dict, args) -> str:
    by = {(r["variant"], r["batch"]): r for r in rows}
    batches = sorted({r["batch"] for r in rows})
    lines = [f"- date: {env['date']}", f"- device: {env['device']} (backend {env['backend']}, "
             f"{env['num_devices']} device(s)); host CPU: {env['cpu']}, {env['cpu_count']} cores",
             f"- python {env['python']}, jax {env['jax']}, jaxlib {env['jaxlib']}, gymnax {env['gymnax'] or '-'}",
             f"- steps per call: {args.steps}, repeats: {args.repeats} (best shown), scan unroll: {args.unroll}",
             f"- command: `{env['command']}`", ""]
    if lengths:
        lines += ["Mean episode length (env-steps per finished episode, B=4096, 300 steps): "
                  + ", ".join(f"{v} {x:.1f}" for v, x in lengths.items()), ""]
    head = ["batch"] + [f"{v} steps/s" for v in variants]
    has_g = "gymnax" in variants
    if has_g and "auto" in variants:
        head.append("auto / gymnax")
    if has_g and "auto-split" in variants:
        head.append("auto-split / gymnax")
    if "step" in variants and "auto" in variants:
        head.append("step / auto (reset cost)")
    head.append("compile s (" + ", ".join(variants) + ")")
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for b in batches:
        cells = [str(b)] + [fmt(by[(v, b)]["steps_per_s"]) if (v, b) in by else "-" for v in variants]
        if has_g and "auto" in variants:
            cells.append(fmt(ratio(by.get(("auto", b)), by.get(("gymnax", b)))))
        if has_g and "auto-split" in variants:
            cells.append(fmt(ratio(by.get(("auto-split", b)), by.get(("gymnax", b)))))
        if "step" in variants and "auto" in variants:
            cells.append(fmt(ratio(by.get(("step", b)), by.get(("auto", b)))))
        cells.append(", ".join(f"{by[(v, b)]['compile_s']:.2f}" if (v, b) in by else "-" for v in variants))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------- CLI


def write_report(out: str, table: str, payload: dict) -> None:
    """Writes the markdown ``table`` and the JSON ``payload`` next to each other: ``out`` names one of them
    (``.json`` or anything else for the markdown), the other takes the same stem."""
    stem, ext = os.path.splitext(out)
    md, js = (stem + ".md", out) if ext == ".json" else (out, stem + ".json")
    os.makedirs(os.path.dirname(os.path.abspath(md)), exist_ok=True)
    with open(md, "w") as f:
        f.write(table)
    with open(js, "w") as f:
        json.dump(payload, f, indent=1)
    print(f"wrote {md} and {js}")


def parse_batches(text: str) -> list[int]:
    """``1,4,16`` or ``4^0..4^8`` or ``2^0..2^20`` (every power in between), or a mix, comma-separated."""
    out = []
    for part in text.split(","):
        part = part.strip()
        if ".." in part:
            lo, hi = part.split("..")
            base, e0 = (int(x) for x in lo.split("^"))
            base1, e1 = (int(x) for x in hi.split("^"))
            if base != base1:
                raise argparse.ArgumentTypeError(f"range {part!r} mixes bases {base} and {base1}")
            out += [base**e for e in range(e0, e1 + 1)]
        elif "^" in part:
            base, e = (int(x) for x in part.split("^"))
            out.append(base**e)
        else:
            out.append(int(part))
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"batch sizes must be positive integers, got {text!r}")
    return sorted(set(out))


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog="Defaults depend on the backend: "
                                "on CPU batches 4^0..4^8 and 200 steps, on accelerators 4^0..4^10 (2^20) and "
                                "1000 steps.", formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--batch-sizes", type=parse_batches, default=None,
                   help="comma-separated batch sizes; 'B^i..B^j' expands to powers (e.g. 4^0..4^10)")
    p.add_argument("--steps", type=int, default=None, help="steps per timed call (one lax.scan)")
    p.add_argument("--repeats", type=int, default=5,
                   help="timed calls per variant after one warm-up, interleaved across variants; best shown")
    p.add_argument("--unroll", type=int, default=1, help="lax.scan unroll, the same for every variant")
    p.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                   help=f"comma-separated subset of {','.join(ALL_VARIANTS)}")
    p.add_argument("--peers", choices=("auto", "gymnax", "none"), default="auto",
                   help="auto: compare with gymnax if it is installed, else say so and skip it; "
                        "gymnax: require it; none: run ours alone")
    p.add_argument("--out", default=None, help="write the table to this .md file and the raw numbers beside it "
                   "as .json (or the other way round when it ends in .json)")
    p.add_argument("--dump-hlo", metavar="DIR", default=None,
                   help="write each compiled program's optimised HLO to DIR (to read what XLA made of a loop)")
    p.add_argument("--no-check", action="store_true", help="skip the episode-length check before timing")
    args = p.parse_args(argv)
    gpu = jax.default_backend() != "cpu"
    args.batch_sizes = args.batch_sizes or [4**i for i in range(11 if gpu else 9)]
    args.steps = args.steps or (1000 if gpu else 200)
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    bad = [v for v in variants if v not in ALL_VARIANTS]
    if bad:
        p.error(f"unknown variant(s) {bad}; choose from {list(ALL_VARIANTS)}")
    if args.peers != "none" and any(v in PEERS for v in variants):
        try:
            import gymnax  # noqa: F401
        except ImportError as e:
            if args.peers == "gymnax":
                p.error(f"--peers gymnax, but gymnax does not import ({e}); install it with "
                        "`pip install gymnax` (or `pip install -e .[bench]`)")
            print(f"note: gymnax does not import ({e}): skipping the gymnax variants. Install it with "
                  "`pip install gymnax` to compare, or pass --peers none to silence this.", file=sys.stderr)
            args.peers = "none"
    if args.peers == "none":
        variants = [v for v in variants if v not in PEERS]
    args.variant_list = variants
    return args


def main(argv=None) -> int:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    args = parse_args(argv)
    env = environment()
    print(f"# {ARENA} on {env['device']} ({env['backend']}), jax {env['jax']}, gymnax {env['gymnax']}", flush=True)
    lengths = {}
    if not args.no_check:
        for v in args.variant_list:
            if v != "step":
                lengths[v] = mean_episode_length(v)
        if lengths:
            print("mean episode length: " + ", ".join(f"{v} {x:.1f}" for v, x in lengths.items()), flush=True)
    rows = []
    for b in args.batch_sizes:
        for r in time_batch(args.variant_list, b, args.steps, args.repeats, args.unroll, dump_hlo=args.dump_hlo):
            v = r["variant"]
            rows.append(r)
            print(f"B={b:>8} {v:>11}: {r['steps_per_s']:.3e} steps/s (median {r['steps_per_s_median']:.3e}), "
                  f"{r['best_s'] * 1e3:.2f} ms/call, compile {r['compile_s']:.2f} s", flush=True)
    table = markdown(env, rows, args.variant_list, lengths, args)
    print()
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": dict(vars(args)), "episode_length": lengths,
                                       "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
