"""A third-party trainer on a jarena arena: Stable-Baselines3's PPO through ``jarena.interop.to_gymnasium``.

    pip install "jarena[sb3]"              # Stable-Baselines3, which brings PyTorch (not a jarena dependency)
    python examples/sb3_through_gymnasium_export.py                      # both envs, seed 0
    python examples/sb3_through_gymnasium_export.py --env jarena --seed 3

Trains SB3's PPO with rl-baselines3-zoo's CartPole-v1 hyperparameters on ``classic|domain:cartpole,task:balance``
exported as Gymnasium envs (SB3 vectorises them with its own ``DummyVecEnv``), and, as the peer, on Gymnasium's
own ``CartPole-v1`` with the same settings and seed. Prints one table row per run: the mean and standard
deviation of the return over 20 evaluation episodes (SB3's ``evaluate_policy``, deterministic actions) and the
training time. Nothing here is jarena-specific but the one line that builds the env: that is the point.
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

import jarena
from jarena.interop.gymnasium import to_gymnasium

ARENA = "classic|domain:cartpole,task:balance"
ENVS = {"jarena": lambda: to_gymnasium(jarena.build_arena(ARENA)), "gymnasium": lambda: gymnasium.make("CartPole-v1")}
"""Env name -> a factory of one Gymnasium env: jarena's arena through the export, or Gymnasium's own."""


def zoo_ppo(env, seed: int) -> PPO:
    """rl-baselines3-zoo's tuned PPO for CartPole-v1 (``hyperparams/ppo.yml``; 8 envs, 100k steps)."""
    return PPO("MlpPolicy", env, n_steps=32, batch_size=256, gae_lambda=0.8, gamma=0.98, n_epochs=20, ent_coef=0.0,
               learning_rate=lambda progress: progress * 1e-3, clip_range=lambda progress: progress * 0.2,
               seed=seed, verbose=0)


def train_and_evaluate(env_name: str, seed: int, steps: int) -> dict:
    """One SB3 run on ``env_name``: ``{"env", "seed", "steps", "return_mean", "return_std", "train_seconds"}``."""
    vec_env = make_vec_env(ENVS[env_name], n_envs=8, seed=seed)
    model = zoo_ppo(vec_env, seed)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - start
    eval_env = Monitor(ENVS[env_name]())
    eval_env.reset(seed=10_000 + seed)
    mean, std = evaluate_policy(model, eval_env, n_eval_episodes=20, deterministic=True)
    return dict(env=env_name, seed=seed, steps=steps, return_mean=float(mean), return_std=float(std),
                train_seconds=seconds)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", choices=[*ENVS, "both"], default="both", help="which CartPole (default both)")
    p.add_argument("--seed", type=int, default=0, help="seed of the run (default 0)")
    p.add_argument("--steps", type=int, default=100_000, help="environment steps (default 100000, the zoo's)")
    p.add_argument("--json", action="store_true", help="print each run as a JSON line as well")
    args = p.parse_args(argv)
    print("| env | seed | steps | eval return (20 episodes) | training seconds |")
    print("|---|---:|---:|---:|---:|")
    for name in ENVS if args.env == "both" else [args.env]:
        row = train_and_evaluate(name, args.seed, args.steps)
        print(f"| {name} | {row['seed']} | {row['steps']} | {row['return_mean']:.1f} +- {row['return_std']:.1f} | "
              f"{row['train_seconds']:.0f} |", flush=True)
        if args.json:
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
