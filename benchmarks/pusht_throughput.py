"""PushT actions per second: jarena's batched arena against the pymunk scene Diffusion Policy's environment steps.

jarena: ``pusht|obs:state`` and ``pusht|obs:image`` (96 x 96 RGB drawn on the device), a batch of B arenas,
``--actions`` actions per call of ``jarena.batch_step`` in one jitted ``lax.scan`` with auto-reset, uniform random
target points; compiled apart, one warm-up call, then ``--repeats`` calls interleaved (best shown, median in the
JSON). One action = 10 physics steps of 10 ms plus the exact coverage (and the image for ``obs:image``).

The peer: the same scene in pymunk (``tests/arenas/pusht/reference.py``: walls, the PD-driven disc and the T, set up
from ``pusht_env``'s facts), one environment per process as Diffusion Policy runs it, with the coverage computed
by shapely after each action as ``pusht_env`` does (``pymunk`` alone: physics only). ``pusht_env`` also draws
its observation with pygame each step; that part is not measured here, so the peer's image rate is an upper bound.

Usage::

    python benchmarks/pusht_throughput.py --batch-sizes 1,64 --actions 10 --repeats 2      # CPU smoke run
    python benchmarks/pusht_throughput.py --out results/pusht_gpu.md                     # GPU: B = 1 ... 4096
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
from jarena.arenas.pusht import geometry  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cartpole_throughput import fmt, parse_batches, write_report  # noqa: E402
from timing import environment, time_interleaved  # noqa: E402

OBS = ("state", "image")


def make(obs: str, batch: int, args):
    """``(run, carry, units)`` for ``batch`` arenas of ``pusht|obs:<obs>``: ``args.actions`` random actions."""
    arena = jarena.build_arena(f"pusht|obs:{obs},auto_reset:lazy")
    params = arena.default_params()
    states, _ = jax.jit(lambda k: jarena.batch_reset(arena, k, batch, params))(jax.random.key(args.seed))

    def run(carry):
        states, key = carry

        def body(states, t):
            actions = jax.random.uniform(jax.random.fold_in(key, t), (batch, 2), minval=0.0, maxval=512.0)
            states, info = jarena.batch_step(arena, states, actions, params, reset_done=True)
            used = sum(jnp.mean(x.astype(jnp.float32)) for x in jax.tree_util.tree_leaves(info.observation))
            return states, info.reward.mean() + used

        states, used = jax.lax.scan(body, states, jnp.arange(args.actions))
        # the key depends on the rewards and observations, so XLA cannot drop their computation
        return states, jax.random.fold_in(key, jax.lax.bitcast_convert_type(jnp.sum(used), jnp.uint32))

    return run, (jax.block_until_ready(states), jax.random.key(args.seed + 1)), batch * args.actions


def time_pymunk(args, with_coverage: bool) -> float:
    """Actions per second of one pymunk scene (best of ``args.repeats`` runs of ``args.peer_actions`` actions)."""
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from arenas.pusht.reference import PymunkPushT
    from shapely import affinity
    from shapely.geometry import Polygon

    boxes = [Polygon(quad) for quad in geometry.box_corners()]
    goal = [affinity.translate(affinity.rotate(b, np.pi / 4, origin=(0, 0), use_radians=True), 256, 256)
            for b in boxes]
    goal_shape = goal[0].union(goal[1])
    rng = np.random.default_rng(args.seed)
    actions = rng.uniform(0, 512, (args.peer_actions, 2))
    best = float("inf")
    for _ in range(args.repeats):
        scene = PymunkPushT((100.0, 100.0), (300.0, 300.0, 0.5))
        t0 = time.perf_counter()
        for action in actions:
            scene.step(action)
            if with_coverage:
                x, y, angle = scene.pose
                block = [affinity.translate(affinity.rotate(b, angle, origin=(0, 0), use_radians=True), x, y)
                         for b in boxes]
                _ = block[0].union(block[1]).intersection(goal_shape).area / goal_shape.area
        best = min(best, time.perf_counter() - t0)
    return args.peer_actions / best


def markdown(env: dict, results: dict, peer: dict, args) -> str:
    lines = [f"PushT actions/s, {env['device']} ({env['backend']}), {env['cpu']} x {env['cpu_count']}, "
             f"jax {env['jax']}, {env['date']}", "",
             f"pymunk + shapely (one environment, one process): {peer['pymunk+shapely']:.0f} actions/s; "
             f"pymunk alone {peer['pymunk']:.0f}", "",
             "| B | obs | jarena actions/s | / pymunk + shapely | compile s |", "|---:|---|---:|---:|---:|"]
    for batch, by_obs in results.items():
        for obs, r in by_obs.items():
            lines.append(f"| {batch} | {obs} | {fmt(r['per_s'])} | {fmt(r['per_s'] / peer['pymunk+shapely'])} | "
                         f"{r['compile_s']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--batch-sizes", type=parse_batches, default=parse_batches("1,64,1024,4096"))
    parser.add_argument("--obs", default="state,image", help=f"comma-separated, of {OBS}")
    parser.add_argument("--actions", type=int, default=100, help="actions per timed call")
    parser.add_argument("--peer-actions", type=int, default=300, help="actions per timed pymunk run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="write the table (.md) and data (.json) here")
    args = parser.parse_args(argv)
    observations = [o for o in args.obs.split(",") if o]
    for o in observations:
        if o not in OBS:
            parser.error(f"unknown obs {o!r}; valid: {', '.join(OBS)}")
    env = environment()
    peer = {"pymunk": time_pymunk(args, False), "pymunk+shapely": time_pymunk(args, True)}
    print(f"peer: {peer}", flush=True)
    results = {}
    for batch in args.batch_sizes:
        makers = {o: (lambda o=o: make(o, batch, args)) for o in observations}
        results[batch] = time_interleaved(makers, args.repeats, label=f"B={batch:<6d}")
    table = markdown(env, results, peer, args)
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": {k: str(v) for k, v in vars(args).items()},
                                       "peer": peer, "results": {str(b): r for b, r in results.items()}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
