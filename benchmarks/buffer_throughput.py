"""Add and sample throughput (items/s) of ``jarena.data``'s buffer against flashbax's trajectory buffer.

Both buffers hold the same items (a dict of 17-float observation and next observation, 6-float action,
reward, flags, episode id and step: 174 bytes) from B arenas, ``--capacity`` items in all, and run on
the same device. Every call is jitted (the add with the state donated); after a warm-up call, the
variants compared take turns call by call (so a machine whose load drifts treats them alike), each
call timed with ``time.perf_counter`` around ``jax.block_until_ready``; the figures are medians over
``--calls`` calls (dispatch and the per-call sync included, for every variant alike).

- add: one step of B arenas per call (ours (B, ...), flashbax (B, 1, ...)); ``--chunk`` steps per call
  (ours (T, B, ...), flashbax (B, T, ...)); and ``--loop`` one-step adds inside one compiled loop, as in
  a collection loop. Also the add's cost against copying the added bytes (``np.copyto`` into successive
  rows of a buffer-sized array, and a jitted copy of the batch), and against the same add on a smaller
  buffer (``max(capacity / B / 64, --loop)`` steps per arena; an add that copied the whole buffer would
  scale with its size).
- sample: S items per call: transitions (flashbax: sequences of 1), windows of L items crossing episodes
  (ours ``window_across``; flashbax: sequences of L), and ours alone: windows inside one episode
  (``window``) and whole episodes padded to 200 (``trajectory``). Episodes last 200 steps.

Usage::

    python benchmarks/buffer_throughput.py                       # CPU, 1M items, B=1024
    PYTHONPATH=/path/to/flashbax python benchmarks/buffer_throughput.py --out results.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

try:
    import jarena
except ImportError:  # run from a checkout without installing
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena

EPISODE = 200


def stream(num_arenas: int, t0: int, steps: int) -> dict:
    """Items of ``steps`` steps of B arenas from time t0, leaves (T, B, ...); episodes of 200 steps, staggered."""
    t = t0 + jnp.arange(steps)[:, None] + jnp.arange(num_arenas)[None] * 37
    step = (t % EPISODE).astype(jnp.int32)
    obs = jnp.sin(t[..., None] * 0.01 + jnp.arange(17)).astype(jnp.float32)
    return {"observation": {"state": obs}, "next_observation": {"state": obs + 1.0},
            "action": jnp.cos(t[..., None] + jnp.arange(6)).astype(jnp.float32),
            "reward": (t * 0.1).astype(jnp.float32), "terminated": step == EPISODE - 1,
            "truncated": jnp.zeros(t.shape, bool), "episode": (t // EPISODE + jnp.arange(num_arenas) * 100000
                                                               ).astype(jnp.int32), "step": step}


def nbytes(tree) -> int:
    return sum(x.nbytes for x in jax.tree_util.tree_leaves(tree))


def timed(fns: dict, calls: int) -> dict[str, float]:
    """Median seconds per call of each ``fn(i)``; the functions take turns call by call (A/B/A/B...), each
    call blocked on, so that a machine whose load drifts treats them alike. One warm-up call each."""
    for fn in fns.values():
        jax.block_until_ready(fn(0))
    times = {name: [] for name in fns}
    for i in range(calls):
        for name, fn in fns.items():
            start = time.perf_counter()
            jax.block_until_ready(fn(i))
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}


# ---------------------------------------------------------------------------------------------- ours
def ours(num_arenas: int, capacity: int, batch: int, length: int):
    item = jax.tree_util.tree_map(lambda x: x[0, 0], stream(num_arenas, 0, 1))
    buffers = {mode: jarena.data.make_buffer(num_arenas, capacity, batch, mode=mode,
                                             length=None if mode == "transition" else
                                             (EPISODE if mode == "trajectory" else length))
               for mode in ("transition", "window_across", "window", "trajectory")}
    return item, buffers


def fill_ours(buffer, item, num_arenas, per_arena, chunk=64):
    add = jax.jit(buffer.add, donate_argnums=0)
    state = buffer.init(item)
    for t0 in range(0, per_arena, chunk):
        state = add(state, stream(num_arenas, t0, chunk))
    return state


# ---------------------------------------------------------------------------------------------- flashbax
def flashbax_buffers(num_arenas: int, per_arena: int, batch: int, length: int):
    import flashbax

    return {name: flashbax.make_trajectory_buffer(add_batch_size=num_arenas, sample_batch_size=batch,
                                                  sample_sequence_length=seq, period=1, min_length_time_axis=seq,
                                                  max_length_time_axis=per_arena)
            for name, seq in (("transition", 1), ("window_across", length))}


def batch_major(tree):
    return jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), tree)


def fill_flashbax(buffer, item, num_arenas, per_arena, chunk=64):
    add = jax.jit(buffer.add, donate_argnums=0)
    state = buffer.init(item)
    for t0 in range(0, per_arena, chunk):
        state = add(state, batch_major(stream(num_arenas, t0, chunk)))
    return state


# ---------------------------------------------------------------------------------------------- runs
def _adder(add, init, batch):
    """``(call, in_place)``: ``call(i)`` adds ``batch`` to a donated state; ``in_place()`` says whether the
    state's first leaf still lives where it started."""
    state = [init()]
    first = jax.tree_util.tree_leaves(state[0])[0].unsafe_buffer_pointer()

    def call(i):
        state[0] = add(state[0], batch)
        return state[0]

    return call, lambda: jax.tree_util.tree_leaves(state[0])[0].unsafe_buffer_pointer() == first


def _looped(add, steps, flashbax_layout):
    """``steps`` one-step adds inside one compiled loop (as in a collection loop); the batch is (K, B, ...)."""
    def many(state, batch):
        def body(i, state):
            one = jax.tree_util.tree_map(lambda x: jax.lax.dynamic_index_in_dim(x, i, 0, keepdims=False), batch)
            if flashbax_layout:
                one = jax.tree_util.tree_map(lambda x: x[:, None], one)
            return add(state, one)

        return jax.lax.fori_loop(0, steps, body, state)

    return jax.jit(many, donate_argnums=0)


def bench_adds(args, item, results):
    b, per_arena = args.arenas, args.capacity // args.arenas
    small_per_arena = max(per_arena // 64, args.loop)
    for kind, steps in (("call", 1), ("call", args.chunk), ("loop", args.loop)):
        batch = stream(b, 0, steps)
        added = nbytes(batch)
        row = {"kind": kind, "steps_per_call": steps, "items_per_call": b * steps, "bytes_per_call": added}
        fns, checks = {}, {}
        for capacity_per_arena, tag in ((per_arena, "ours"), (small_per_arena, "ours_small")):
            buffer = jarena.data.make_buffer(b, b * capacity_per_arena, args.batch)
            if kind == "loop":
                add, data = _looped(buffer.add, steps, False), batch
            else:
                add = jax.jit(buffer.add, donate_argnums=0)
                data = jax.tree_util.tree_map(lambda x: x[0], batch) if steps == 1 else batch
            fns[tag], checks[tag] = _adder(add, lambda buffer=buffer: buffer.init(item), data)
        if args.flashbax:
            import flashbax

            other = flashbax.make_trajectory_buffer(add_batch_size=b, sample_batch_size=args.batch,
                                                    sample_sequence_length=1, period=1, min_length_time_axis=1,
                                                    max_length_time_axis=per_arena)
            fadd = _looped(other.add, steps, True) if kind == "loop" else jax.jit(other.add, donate_argnums=0)
            fns["flashbax"], _ = _adder(fadd, lambda other=other: other.init(item),
                                        batch if kind == "loop" else batch_major(batch))
        # Copying the added bytes into a buffer-sized array, row after row (cold memory, as a ring write).
        src = np.ones(added, np.uint8)
        rows = np.ones((max(args.capacity * nbytes(item) // added, 2), added), np.uint8)  # pages touched
        fns["memcpy"] = lambda i, rows=rows, src=src: np.copyto(rows[i % rows.shape[0]], src)
        copy = jax.jit(lambda t: jax.tree_util.tree_map(lambda x: x + jnp.zeros((), x.dtype), t))
        fns["jit_copy"] = lambda i, batch=batch: copy(batch)
        seconds = timed(fns, args.calls)
        del fns, rows
        row.update({f"{name}_s": t for name, t in seconds.items()})
        row.update({f"{name}_in_place": check() for name, check in checks.items()})
        for name in ("ours", "flashbax"):
            if name in seconds:
                row[f"{name}_items_per_s"] = b * steps / seconds[name]
        row["ours_over_memcpy"] = seconds["ours"] / seconds["memcpy"]
        row["ours_over_jit_copy"] = seconds["ours"] / seconds["jit_copy"]
        row["small_buffer_items"] = b * small_per_arena
        results["add"].append(row)
        print(json.dumps(row), flush=True)


def bench_samples(args, item, results):
    b, per_arena = args.arenas, args.capacity // args.arenas
    _, buffers = ours(b, args.capacity, args.batch, args.length)
    state = fill_ours(buffers["transition"], item, b, per_arena)
    others = {}
    if args.flashbax:
        fbs = flashbax_buffers(b, per_arena, args.batch, args.length)
        fstate = fill_flashbax(fbs["transition"], item, b, per_arena)
        others = {name: (jax.jit(fb.sample), fstate) for name, fb in fbs.items()}
    keys = jax.random.split(jax.random.key(0), args.calls)
    for mode, buffer in buffers.items():
        sample = jax.jit(buffer.sample)
        out = sample(state, keys[0])
        items = int(np.prod(out.mask.shape))
        fns = {"ours": lambda i, sample=sample: sample(state, keys[i])}
        if mode in others:
            fsample, fstate = others[mode]
            fns["flashbax"] = lambda i, fsample=fsample, fstate=fstate: fsample(fstate, keys[i])
        seconds = timed(fns, args.calls)
        row = {"mode": mode, "items_per_sample": items, "ours_valid_fraction": float(np.mean(out.mask))}
        for name, t in seconds.items():
            row.update({f"{name}_s": t, f"{name}_items_per_s": items / t})
        results["sample"].append(row)
        print(json.dumps(row), flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arenas", type=int, default=1024, help="B, arenas per add")
    parser.add_argument("--capacity", type=int, default=1 << 20, help="items in all")
    parser.add_argument("--batch", type=int, default=256, help="S, units per sample")
    parser.add_argument("--length", type=int, default=8, help="L, window length")
    parser.add_argument("--chunk", type=int, default=16, help="steps per add in the chunked add")
    parser.add_argument("--loop", type=int, default=64, help="one-step adds per call in the looped add")
    parser.add_argument("--calls", type=int, default=500, help="timed calls of each variant (medians kept)")
    parser.add_argument("--no-flashbax", dest="flashbax", action="store_false")
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    args = parser.parse_args(argv)
    if args.flashbax:
        try:
            import flashbax  # noqa: F401
        except Exception as e:  # report the exact error and measure ours alone
            print(f"flashbax unavailable: {type(e).__name__}: {e}", flush=True)
            args.flashbax = False
    item = jax.tree_util.tree_map(lambda x: x[0, 0], stream(args.arenas, 0, 1))
    results = {"args": vars(args), "device": str(jax.devices()[0]), "item_bytes": nbytes(item), "add": [],
               "sample": []}
    bench_adds(args, item, results)
    bench_samples(args, item, results)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
