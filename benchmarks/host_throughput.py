"""Steps per second across the Gymnasium boundary, both ways, each against its peer in the same run.

For each batch size B, ``--steps`` steps with uniformly random actions and auto-reset, best of ``--repeats``
timed calls after a warm-up (calls interleaved across measurements):

- ``host``: a host arena, ``gym|id:<env>`` (default CartPole-v1, the cheapest step: the worst case for the
  overhead; ``--env HalfCheetah-v5`` a MuJoCo one, with Gymnasium's ``mujoco`` extra) behind ``jarena.arenas.host``:
  ``jarena.batch_step`` in a jitted ``lax.scan``, actions drawn in JAX; each step is one host call into a
  ``SyncVectorEnv`` of B envs (and one more in steps where an episode ended, to restart it).
- ``bare``: its peer, the same ``SyncVectorEnv`` of B envs stepped directly from a Python loop
  (``AutoresetMode.SAME_STEP``, actions sampled from its action space). Goal: ``host`` costs at most 1.2x
  ``bare`` per step.
- ``export``: the other way, ``to_gymnasium_vector("classic|domain:cartpole", B)`` stepped from a Python loop
  with numpy actions, as a Gymnasium user would, against ``bare`` (Gymnasium's own CartPole, same API).

Usage::

    python benchmarks/host_throughput.py --help
    python benchmarks/host_throughput.py --batch-sizes 1,8 --steps 200 --repeats 2   # smoke run
    python benchmarks/host_throughput.py --out results/host_cpu.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax
import jax.numpy as jnp

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
import gymnasium  # noqa: E402
from gymnasium.vector import AutoresetMode, SyncVectorEnv  # noqa: E402

from jarena.interop.gymnasium import to_gymnasium_vector  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from timing import environment  # noqa: E402

#: The export is measured on the env that jarena has in JAX too (``classic|domain:cartpole`` is CartPole-v1).
EXPORTED = {"CartPole-v1": "classic|domain:cartpole"}


def host_run(env_id: str, batch: int, steps: int):
    arena = jarena.build_arena(f"gym|id:{env_id}")

    def body(carry, t):
        state, key = carry
        action = jax.vmap(arena.sample_action)(jax.random.split(jax.random.fold_in(key, t), batch))
        state, info = jarena.batch_step(arena, state, action)
        return (state, key), info.reward.sum()

    run = jax.jit(lambda carry: jax.lax.scan(body, carry, jnp.arange(steps)))
    carry = (jarena.batch_reset(arena, jax.random.key(0), batch)[0], jax.random.key(1))

    def call():
        nonlocal carry
        carry, rewards = jax.block_until_ready(run(carry))
        return rewards

    return call


def _python_loop(env, steps: int):
    """Steps a Gymnasium vector env ``steps`` times from Python with actions sampled from its action space."""
    env.reset(seed=0)
    env.action_space.seed(0)

    def call():
        total = 0.0
        for _ in range(steps):
            total += env.step(env.action_space.sample())[1].sum()
        return total

    return call


def bare_run(env_id: str, batch: int, steps: int):
    env = SyncVectorEnv([lambda: gymnasium.make(env_id)] * batch, autoreset_mode=AutoresetMode.SAME_STEP)
    return _python_loop(env, steps)


def export_run(env_id: str, batch: int, steps: int):
    return _python_loop(to_gymnasium_vector(jarena.build_arena(EXPORTED[env_id]), batch), steps)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--env", default="CartPole-v1", help="Gymnasium env id (the export is measured for "
                        f"{', '.join(EXPORTED)})")
    parser.add_argument("--batch-sizes", default="1,8,64,256", help="comma-separated batch sizes B")
    parser.add_argument("--steps", type=int, default=1000, help="steps per timed call")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per measurement (best kept)")
    parser.add_argument("--out", help="write the results as JSON here")
    args = parser.parse_args(argv)
    results = {"environment": environment(env=args.env, steps=args.steps), "rows": []}
    makers = {"host": host_run, "bare": bare_run, **({"export": export_run} if args.env in EXPORTED else {})}
    for batch in [int(b) for b in args.batch_sizes.split(",")]:
        calls = {name: make(args.env, batch, args.steps) for name, make in makers.items()}
        for call in calls.values():
            call()  # compile and warm up
        times = {name: [] for name in calls}
        for _ in range(args.repeats):
            for name, call in calls.items():
                t0 = time.perf_counter()
                call()
                times[name].append(time.perf_counter() - t0)
        row = {"batch": batch, **{f"{name}_steps_per_s": batch * args.steps / min(t) for name, t in times.items()}}
        row["host_cost_vs_bare"] = row["bare_steps_per_s"] / row["host_steps_per_s"]
        line = (f"B={batch:5d}  host {row['host_steps_per_s']:10.0f}/s  bare {row['bare_steps_per_s']:10.0f}/s  "
                f"host cost {row['host_cost_vs_bare']:.2f}x bare")
        if "export" in calls:
            row["export_speed_vs_bare"] = row["export_steps_per_s"] / row["bare_steps_per_s"]
            line += f"  export {row['export_steps_per_s']:10.0f}/s = {row['export_speed_vs_bare']:.2f}x bare"
        results["rows"].append(row)
        print(line, flush=True)
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as f:
            json.dump(results, f, indent=2)
    return results


if __name__ == "__main__":
    main()
