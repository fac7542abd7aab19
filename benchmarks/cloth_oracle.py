"""The corner-pulling oracle on crumpled cloths: how often it flattens within a few actions (issue 17's bar).

The bar: normalised coverage >= 0.9 within 10 pick-and-place actions on at least 90% of the crumpled eval
episodes. All episodes run in one batch, one compiled scan over the actions; prints the initial, final and
best coverage of each episode and the counts reaching 0.9 and 0.99.

    python benchmarks/cloth_oracle.py --particles 40 --episodes 64 --actions 10
"""

from __future__ import annotations

import argparse
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import jarena
from jarena_agents import build_agent


def run(particles: int, episodes: int, actions: int, tool: str):
    arena = jarena.build_arena(f"cloth|domain:square_fabric,initial:crumpled,particles:{particles},"
                               f"task:flattening,action:{tool},horizon:{actions},eval_episodes:{episodes}")
    agent = build_agent("oracle_cloth_flattening")
    ids = jnp.asarray(list(arena.episodes("eval")))

    @jax.jit
    def go(ids):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(ids)
        agent_state = agent.init(jax.random.key(0), arena.spec, ids.shape[0])

        def body(carry, key):
            state, info, agent_state = carry
            action, agent_state = agent.act(agent_state, info, key, arena.privileged(state))
            state, info = jax.vmap(arena.step)(state, action)
            return (state, info, agent_state), info.metrics["normalised_coverage"]

        _, coverage = jax.lax.scan(body, (state, info, agent_state), jax.random.split(jax.random.key(1), actions))
        return info.metrics["normalised_coverage"], coverage

    start = time.perf_counter()
    initial, coverage = jax.block_until_ready(go(ids))
    return np.asarray(initial), np.asarray(coverage), time.perf_counter() - start


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--particles", type=int, default=40, help="particles along a side (default 40)")
    p.add_argument("--episodes", type=int, default=64, help="crumpled eval episodes (default 64)")
    p.add_argument("--actions", type=int, default=10, help="pick-and-place actions per episode (default 10)")
    p.add_argument("--tool", default="pixel_pick_and_place(1)", help="action tool (default pixel_pick_and_place(1))")
    args = p.parse_args(argv)
    initial, coverage, seconds = run(args.particles, args.episodes, args.actions, args.tool)
    best = coverage.max(0)
    np.set_printoptions(precision=2, linewidth=160)
    print(f"{jax.devices()[0].device_kind}, jax {jax.__version__}, Python {platform.python_version()}")
    print("initial normalised coverage:", initial)
    print("final:", coverage[-1])
    print("best within the episode:", best)
    print("| particles | episodes | actions | initial (mean) | final (mean) | reach 0.9 | reach 0.99 | seconds |")
    print(f"| {args.particles} | {args.episodes} | {args.actions} | {initial.mean():.2f} | {coverage[-1].mean():.2f} | "
          f"{(best >= 0.9).sum()} ({(best >= 0.9).mean():.0%}) | {(best >= 0.99).sum()} | {seconds:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
