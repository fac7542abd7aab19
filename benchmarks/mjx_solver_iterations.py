"""How many iterations MJX's constraint solver and its line search run in jarena's MJX arenas: the loops that bound
a batched physics step's latency on a GPU (a vmapped ``while`` loop runs until its slowest arena is done).

For each arena string, ``--batch`` arenas (one after the other) from their reset take ``--steps`` control steps of
uniform random actions in one jitted ``lax.scan``; every solve reports, per arena, the solver's iterations
(``solver_niter``: it stops when the cost's improvement or the gradient falls under ``opt.tolerance``, or at
``opt.iterations``) and each iteration's line-search steps (at most ``opt.ls_iterations``; as the arenas run the
search, or with ``--mjx-exit-only`` as MJX's own condition alone runs it). Prints per arena string the iterations per
solve (mean, median, 90th percentile, max), the mean over solves of the maximum over the arenas (what a batch of them
runs in a vmapped loop) and the line search's steps per solver iteration. CPU or GPU; the counts do not depend on the
device beyond float rounding.

    python benchmarks/mjx_solver_iterations.py --arenas "dmc|domain:walker,task:walk" "dmc|domain:humanoid,task:walk"
"""

from __future__ import annotations

import argparse
import contextlib
import json
import platform

import jax
import jax.numpy as jnp
import numpy as np

import jarena
from jarena.arenas.mjx import dynamics as mjx_dynamics

SOLVES: list[np.ndarray] = []
SEARCHES: list[np.ndarray] = []


@contextlib.contextmanager
def counted_loops(flat_start_exit: bool = True):
    """While tracing inside it, the solver's outer loop and the line search's loop report their iteration counts;
    the line search runs as the arenas run it (:func:`jarena.arenas.mjx.dynamics._search_loop`), or with
    ``flat_start_exit`` false as MJX's own condition alone runs it (its scan's iterations, without the idle ones)."""
    plain_while, plain_search = jax.lax.while_loop, mjx_dynamics._while_loop

    def while_loop(cond, body, init):
        out = plain_while(cond, body, init)
        if hasattr(out, "solver_niter") and hasattr(out, "prev_cost"):  # mjx solver.Context
            jax.debug.callback(lambda n: SOLVES.append(np.asarray(n).reshape(-1)), out.solver_niter)
        return out

    def search(cond_fun, body_fun, init_val, max_iter):
        out, steps = mjx_dynamics._search_loop(cond_fun, body_fun, init_val, max_iter, flat_start_exit)
        jax.debug.callback(lambda n: SEARCHES.append(np.asarray(n).reshape(-1)), steps)
        return out

    jax.lax.while_loop, mjx_dynamics._while_loop = while_loop, search
    try:
        yield
    finally:
        jax.lax.while_loop, mjx_dynamics._while_loop = plain_while, plain_search


def summary(counts: np.ndarray) -> dict:
    return dict(mean=round(float(counts.mean()), 2), median=float(np.median(counts)),
                p90=float(np.percentile(counts, 90)), max=int(counts.max()))


def measure(name: str, batch: int, steps: int, flat_start_exit: bool = True) -> dict:
    SOLVES.clear(), SEARCHES.clear()
    arena = jarena.build_arena(name)
    params = arena.default_params()
    spec = arena.spec.action
    low, high = jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)

    def step(state, key):
        action = jax.random.uniform(key, tuple(spec.shape), minval=low, maxval=high)
        return arena.step(state, action, params)[0], None

    def one_arena(key):
        state, _ = arena.reset(key, params)
        return jax.lax.scan(step, state, jax.random.split(key, steps))[0]

    # one arena at a time (lax.map, not vmap), so that each count is that arena's own: a batched loop keeps
    # running its finished members' bodies until the slowest is done
    with counted_loops(flat_start_exit):
        jax.block_until_ready(jax.jit(lambda k: jax.lax.map(one_arena, jax.random.split(k, batch)))(
            jax.random.key(0)))
    solves = np.concatenate(SOLVES).reshape(batch, -1)  # arena-major: every arena makes the same solves
    return dict(arena=name, arenas=batch, steps=steps, solves_per_arena=solves.shape[1],
                solver_iterations=summary(solves),
                solver_iterations_batch_max_mean=round(float(solves.max(axis=0).mean()), 2),
                line_search_steps=summary(np.concatenate(SEARCHES)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--arenas", nargs="+", default=["dmc|domain:walker,task:walk"])
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--steps", type=int, default=50, help="control steps per arena")
    parser.add_argument("--mjx-exit-only", action="store_true",
                        help="count the line search as MJX's condition alone runs it, without the arenas' exit at a "
                             "flat start")
    args = parser.parse_args()
    print(f"# {jax.devices()[0].device_kind}, jax {jax.__version__}, Python {platform.python_version()}")
    for name in args.arenas:
        print(json.dumps(measure(name, args.batch, args.steps, not args.mjx_exit_only)), flush=True)


if __name__ == "__main__":
    main()
