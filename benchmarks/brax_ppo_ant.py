"""Brax's own PPO on ant with its published settings: the peer run for ``configs/ppo/brax-ant-positional``.

The trainers of brax 0.14.2 fail on jax >= 0.10; Brax's main branch works. Clone it
(github.com/google/brax) and point ``--brax`` at the clone (the folder holding the ``brax`` package).
Settings: the "ant" entry of Brax's ``notebooks/training.ipynb``. Prints each evaluation's return and the
wall clock (compile and evaluations included), to set beside
``jarena train ppo "brax|env:ant,backend:positional"``. Usage::

    python benchmarks/brax_ppo_ant.py --brax ~/brax --backend positional
"""

from __future__ import annotations

import argparse
import functools
import sys
import time


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--brax", required=True, help="folder holding Brax's main-branch `brax` package")
    parser.add_argument("--backend", default="positional", help="Brax backend (positional, mjx, generalized, spring)")
    parser.add_argument("--steps", type=int, default=50_000_000, help="environment steps (Brax's: 50M)")
    args = parser.parse_args(argv)
    sys.path.insert(0, args.brax)
    import brax
    from brax import envs
    from brax.training.agents.ppo import train as ppo

    print(f"brax from {brax.__file__}, backend {args.backend}", flush=True)
    start = time.time()

    def progress(step, metrics):
        print(f"  {step:>10d} steps  eval return {float(metrics['eval/episode_reward']):8.1f}  "
              f"{time.time() - start:6.1f} s", flush=True)

    train = functools.partial(ppo.train, num_timesteps=args.steps, num_evals=10, reward_scaling=10,
                              episode_length=1000, normalize_observations=True, action_repeat=1, unroll_length=5,
                              num_minibatches=32, num_updates_per_batch=4, discounting=0.97, learning_rate=3e-4,
                              entropy_cost=1e-2, num_envs=4096, batch_size=2048, seed=1)
    train(environment=envs.get_environment("ant", backend=args.backend), progress_fn=progress)
    print(f"brax ppo ant: {time.time() - start:.1f} s (compile and evaluations included)")


if __name__ == "__main__":
    main()
