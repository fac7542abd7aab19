"""The cloth oracles against the random agent on the cloth eval episodes (their quality bars).

Flattening (crumpled starts): the bar is normalised coverage >= 0.9 within 10 pick-and-place actions on at
least 90% of the eval episodes; episodes are also grouped in difficulty tiers by their initial coverage
(:func:`jarena.arenas.cloth.tiers.difficulty_tiers`). Folds (flat starts): the task's success (normalised fold
distance <= 0.1) and the normalised fold distance reached. Each (task, agent) runs all its episodes in one
batch, one compiled scan over the actions, and prints one table row.

    python benchmarks/cloth_oracle.py --tasks flattening --agents oracle,random --episodes 64 --actions 10
    python benchmarks/cloth_oracle.py --agents oracle --config '{"lookahead": false}'   # the analytic pull alone
    python benchmarks/cloth_oracle.py --tasks side_fold,diagonal_fold,one_corner_inward --initial flat --actions 4
    python benchmarks/cloth_oracle.py --agents bc --checkpoint runs/bc --extra resolution:64,depth:false,mask:false
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import jarena
from jarena.arenas.cloth import tiers as tiers_lib
from jarena.runners.loop import act_and_step
from jarena.training import restore_policy
from jarena_agents import build_agent, list_agents

ORACLES = {"flattening": "oracle_cloth_flattening"}
"""Task -> its oracle (every fold: ``oracle_cloth_folding``)."""


def arena_string(task: str, initial: str, particles: int, actions: int, episodes: int, tool: str,
                 extra: str = "") -> str:
    return (f"cloth|domain:square_fabric,initial:{initial},particles:{particles},task:{task},action:{tool},"
            f"horizon:{actions},eval_episodes:{episodes}" + (f",{extra}" if extra else ""))


def tuned_config(agent: str, arena) -> dict:
    """The agent's committed config for the arena (``configs/``), else its defaults."""
    try:
        return dict(jarena.retrieve_config(agent, arena))
    except FileNotFoundError:
        return {}


def episode_ids(arena, split: str, count: int) -> jax.Array:
    """int32 (count,): the arena's ``eval`` episodes, or the first ``count`` of its ``train`` range (the episodes
    to tune an oracle's knobs on without fitting the eval episodes)."""
    ids = arena.episodes(split)
    return jnp.asarray(list(ids if split == "eval" else ids[:count]))


def run(arena, agent, actions: int, metric: str, agent_state=None, split: str = "eval", count: int = 0):
    """(initial, per-action metric (A, E), per-action success (A, E), seconds) over the arena's ``split``
    episodes (see :func:`episode_ids`); ``agent_state``: a trained policy's acting state (default: the agent's
    ``init``)."""
    ids = episode_ids(arena, split, count)
    if agent_state is not None:
        agent_state = agent.batch_state(agent_state, ids.shape[0])

    @jax.jit
    def go(ids, agent_state):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(ids)
        if agent_state is None:
            agent_state = agent.init(jax.random.key(0), arena.spec, ids.shape[0])
        params = arena.default_params()

        def body(carry, key):
            state, info, agent_state, _ = act_and_step(agent, arena, *carry, key, params, None, reset_done=False)
            return (state, info, agent_state), (info.metrics[metric], info.success)

        _, (values, success) = jax.lax.scan(body, (state, info, agent_state),
                                            jax.random.split(jax.random.key(1), actions))
        return info.metrics[metric], values, success

    start = time.perf_counter()
    initial, values, success = jax.block_until_ready(go(ids, agent_state))
    return np.asarray(initial), np.asarray(values), np.asarray(success), time.perf_counter() - start


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tasks", default="flattening", help="comma-separated cloth tasks (default flattening)")
    p.add_argument("--agents", default="oracle,random", help="comma-separated: oracle (the task's), random, or "
                                                            "any agent name (default oracle,random)")
    p.add_argument("--initial", default=None, help="initial state (default: crumpled for flattening, flat for folds)")
    p.add_argument("--particles", type=int, default=40, help="particles along a side (default 40)")
    p.add_argument("--episodes", type=int, default=64, help="episodes (default 64)")
    p.add_argument("--split", default="eval", choices=("eval", "train"),
                   help="eval episodes (default), or the first --episodes of the train range (to tune knobs on)")
    p.add_argument("--actions", type=int, default=10, help="pick-and-place actions per episode (default 10)")
    p.add_argument("--tool", default="pixel_pick_and_place(1)", help="action tool (default pixel_pick_and_place(1))")
    p.add_argument("--config", default="{}", help="JSON config for the oracle (default {})")
    p.add_argument("--checkpoint", default=None, metavar="RUN_DIR",
                   help="a `jarena train` run directory: the trainable agent in --agents acts with the run's config "
                        "and its best validated policy (e.g. bc cloned from the oracle)")
    p.add_argument("--extra", default="", help="more arena keys, e.g. resolution:64,depth:false,mask:false")
    args = p.parse_args(argv)
    oracle_config = json.loads(args.config)
    np.set_printoptions(precision=2, linewidth=160)
    print(f"{jax.devices()[0].device_kind}, jax {jax.__version__}, Python {platform.python_version()}")
    rows = []
    for task in args.tasks.split(","):
        folding = task != "flattening"
        initial_state = args.initial or ("flat" if folding else "crumpled")
        arena = jarena.build_arena(arena_string(task, initial_state, args.particles, args.actions, args.episodes,
                                                args.tool, args.extra))
        metric = "normalised_fold_distance" if folding else "normalised_coverage"
        for name in args.agents.split(","):
            agent_name = ORACLES.get(task, "oracle_cloth_folding") if name == "oracle" else name
            config = dict(oracle_config) if name == "oracle" else tuned_config(agent_name, arena)
            if agent_name in list_agents("arena_model"):  # it simulates the arena it acts in
                config["arena"] = arena.build_string
            trained = args.checkpoint and agent_name in list_agents("trainable")
            if trained:
                config = json.loads(Path(args.checkpoint, "config.json").read_text())["config"]
            agent = build_agent(agent_name, config)
            policy = restore_policy(agent, arena, args.checkpoint) if trained else None
            initial, values, success, seconds = run(arena, agent, args.actions, metric, policy, args.split,
                                                    args.episodes)
            best = values.min(0) if folding else values.max(0)
            print(f"{task} {agent_name}: initial {initial}\nfinal {values[-1]}\nbest {best}")
            label = agent_name + (f" {args.config}" if name == "oracle" and oracle_config else "")
            row = {"task": task, "initial_state": initial_state, "split": args.split, "agent": label,
                   "episodes": len(initial), "actions": args.actions, "initial": float(initial.mean()),
                   "final": float(values[-1].mean()), "best": float(best.mean()),
                   "success": int(success.any(0).sum()), "seconds": seconds}
            if not folding:
                row.update(reach_90=int((best >= 0.9).sum()), reach_99=int((best >= 0.99).sum()))
                tier = tiers_lib.difficulty_tiers(initial)
                row["tiers"] = [{"tier": t, "episodes": int((tier == t).sum()),
                                 "reach_90": int(((best >= 0.9) & (tier == t)).sum())}
                                for t in range(len(tiers_lib.TIER_SIZES))]
            rows.append(row)
    print("| task | initial state | split | agent | episodes | actions | initial (mean) | final (mean) | best (mean) | "
          "success | reach 0.9 | reach 0.99 | seconds |")
    for r in rows:
        n = r["episodes"]
        reach = (f"{r['reach_90']} ({r['reach_90'] / n:.0%}) | {r['reach_99']}" if "reach_90" in r else "- | -")
        print(f"| {r['task']} | {r['initial_state']} | {r['split']} | {r['agent']} | {n} | {r['actions']} | "
              f"{r['initial']:.2f} | {r['final']:.2f} | {r['best']:.2f} | {r['success']} ({r['success'] / n:.0%}) | "
              f"{reach} | {r['seconds']:.0f} |")
    for r in rows:
        if "tiers" in r:
            print(f"{r['task']} {r['agent']} by tier (tier: reach 0.9 / episodes):",
                  ", ".join(f"{t['tier']}: {t['reach_90']}/{t['episodes']}" for t in r["tiers"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
