"""Raven pick-and-place actions per second: jarena's batched arena against Ravens itself on PyBullet.

jarena: ``raven|task:<task>``, a batch of B arenas, ``--actions`` actions per call in one jitted ``lax.scan``:
``oracle_raven`` chooses each action from the privileged state (it renders the true heightmap's object mask, as
Ravens' oracle does), the arenas step with auto-reset (one action = the suction primitive's approach, descent,
attachment, carry, descent and release, then settling, on MJX) and return the 320 x 160 colour-and-height
heightmap. Compiled apart, one warm-up call, then ``--repeats`` calls interleaved (best shown, median in the JSON).

The peer: Ravens (google-research/ravens) from a checkout given by ``--ravens PATH``, unmodified, run as its
``demos.py`` collects demonstrations (``Environment(hz=480)``, the task's oracle, ``env.step`` with the UR5's
inverse kinematics and the suction primitive on PyBullet, the three RGB-D cameras rendered after each action;
episodes reset when done or after the task's ``max_steps``) in one process. Its pip package (0.1) ships no
URDF assets, hence the checkout; its ``__init__`` imports TensorFlow for the agents, so only the environment
and task modules are loaded. Peer dependencies: ``pip install -e .[bench-ravens]``. Reported: actions per second
of the whole loop (oracle, step and resets), and of ``env.step`` alone.

Usage::

    git clone https://github.com/google-research/ravens /tmp/ravens
    python benchmarks/raven_throughput.py --ravens /tmp/ravens --batch-sizes 1,16 --actions 4 --repeats 2  # CPU
    python benchmarks/raven_throughput.py --ravens /tmp/ravens --out results/raven_gpu.md     # GPU: B = 1 ... 1024
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import types

import jax
import jax.numpy as jnp
import numpy as np

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
import jarena_agents  # noqa: E402
from jarena.arenas.raven import TASKS  # noqa: E402
from jarena.runners.loop import act_and_step  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cartpole_throughput import fmt, parse_batches, write_report  # noqa: E402
from timing import environment, time_interleaved  # noqa: E402


def make(task: str, batch: int, args):
    """``(run, carry, units)``: ``args.actions`` oracle actions in ``batch`` arenas of ``raven|task:<task>``."""
    arena = jarena.build_arena(f"raven|task:{task}")
    agent = jarena_agents.build_agent("oracle_raven")
    params = arena.default_params()
    key = jax.random.key(args.seed)
    states, info = jax.jit(lambda k: jarena.batch_reset(arena, k, batch, params))(key)
    agent_state = agent.init(key, arena.spec, batch)

    def run(carry):
        states, info, agent_state, key = carry

        def body(carry, t):
            states, info, agent_state = carry
            states, info, agent_state, _ = act_and_step(agent, arena, states, info, agent_state,
                                                        jax.random.fold_in(key, t), params, None, reset_done=True)
            used = sum(jnp.mean(x.astype(jnp.float32)) for x in jax.tree_util.tree_leaves(info.observation))
            return (states, info, agent_state), info.reward.mean() + used

        (states, info, agent_state), used = jax.lax.scan(body, (states, info, agent_state), jnp.arange(args.actions))
        # the next key depends on the observations and rewards, so XLA cannot drop their computation
        return states, info, agent_state, jax.random.fold_in(key, jax.lax.bitcast_convert_type(jnp.sum(used),
                                                                                              jnp.uint32))

    carry = jax.block_until_ready((states, info, agent_state, jax.random.key(args.seed + 1)))
    return run, carry, batch * args.actions


def load_ravens(root: str):
    """Ravens' ``tasks`` module and ``Environment`` class from a checkout, without its package ``__init__``."""
    package = os.path.join(root, "ravens")
    if not os.path.isdir(os.path.join(package, "environments", "assets")):
        raise SystemExit(f"--ravens {root!r}: no ravens/environments/assets there; give a checkout of "
                         "https://github.com/google-research/ravens")
    module = types.ModuleType("ravens")
    module.__path__ = [package]
    sys.modules["ravens"] = module
    from ravens import tasks
    from ravens.environments.environment import Environment
    return tasks, Environment, os.path.join(package, "environments", "assets")


def time_ravens(task_name: str, args) -> dict:
    """Ravens' oracle on PyBullet, one process: actions/s of the whole loop and of ``env.step`` alone, over
    ``args.peer_actions`` actions (the best of ``args.repeats`` runs), and the oracle's episode success."""
    tasks, Environment, assets = load_ravens(args.ravens)
    env = Environment(assets, disp=False, hz=480)
    best, best_step, rewards = float("inf"), float("inf"), []
    for repeat in range(args.repeats):
        seed, actions, step_s, total, done = 2 * repeat + 1, 0, 0.0, 0.0, True
        start = time.perf_counter()
        while actions < args.peer_actions:
            if done:
                task = tasks.names[task_name]()
                task.mode = "test"
                np.random.seed(seed)  # noqa: NPY002 (Ravens draws its layouts from the global generator)
                seed += 2 * args.repeats
                env.set_task(task)
                agent = task.oracle(env)
                obs, info, done, steps, total = env.reset(), None, False, 0, 0.0
            act = agent.act(obs, info)
            t0 = time.perf_counter()
            obs, reward, done, info = env.step(act)
            step_s += time.perf_counter() - t0
            actions, steps, total = actions + 1, steps + 1, total + reward
            done = done or steps >= task.max_steps
            if done:
                rewards.append(total)
        best = min(best, (time.perf_counter() - start) / actions)
        best_step = min(best_step, step_s / actions)
    env.close()
    return {"per_s": 1.0 / best, "step_per_s": 1.0 / best_step, "episodes": len(rewards),
            "success": float(np.mean(np.asarray(rewards) > 0.99)) if rewards else float("nan")}


def markdown(env: dict, results: dict, peers: dict, args) -> str:
    lines = [f"Raven actions/s (oracle + pick-and-place + heightmap), {env['device']} ({env['backend']}), "
             f"{env['cpu']} x {env['cpu_count']}, jax {env['jax']}, {env['date']}", ""]
    for task, peer in peers.items():
        lines.append(f"Ravens on PyBullet, `{task}` (one process, oracle + `env.step` + resets): "
                     f"{peer['per_s']:.3g} actions/s; `env.step` alone {peer['step_per_s']:.3g}; oracle success "
                     f"{peer['success']:.0%} of {peer['episodes']} episodes")
    lines += ["", "| task | B | jarena actions/s | / Ravens (whole loop) | / Ravens `env.step` | compile s |",
              "|---|---:|---:|---:|---:|---:|"]
    for batch, by_task in results.items():
        for task, r in by_task.items():
            peer = peers.get(task)
            lines.append(f"| {task} | {batch} | {fmt(r['per_s'])} | "
                         f"{fmt(r['per_s'] / peer['per_s']) if peer else '-'} | "
                         f"{fmt(r['per_s'] / peer['step_per_s']) if peer else '-'} | {r['compile_s']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="block-insertion,palletizing-boxes",
                        help="comma-separated Raven tasks (raven|task:<name>)")
    parser.add_argument("--batch-sizes", type=parse_batches, default=parse_batches("1,16,128,1024"))
    parser.add_argument("--actions", type=int, default=10, help="actions per timed call of jarena")
    parser.add_argument("--ravens", default=None, help="a checkout of google-research/ravens (the peer); "
                        "without it only jarena runs")
    parser.add_argument("--peer-actions", type=int, default=20, help="actions per timed Ravens run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="write the table (.md) and data (.json) here")
    args = parser.parse_args(argv)
    task_names = [t for t in args.tasks.split(",") if t]
    for task in task_names:
        if task not in TASKS:
            parser.error(f"unknown task {task!r}; valid: {', '.join(TASKS)}")
    env = environment()
    peers = {}
    if args.ravens:
        for task in task_names:
            peers[task] = time_ravens(task, args)
            print(f"Ravens {task}: {peers[task]}", flush=True)
    results = {}
    for batch in args.batch_sizes:
        makers = {t: (lambda t=t: make(t, batch, args)) for t in task_names}
        results[batch] = time_interleaved(makers, args.repeats, label=f"B={batch:<6d}")
    table = markdown(env, results, peers, args)
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": {k: str(v) for k, v in vars(args).items()},
                                       "peers": peers, "results": {str(b): r for b, r in results.items()}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
