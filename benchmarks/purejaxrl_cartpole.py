"""PureJaxRL's PPO on gymnax CartPole-v1, timed as ``benchmarks/ppo_cartpole.py`` times ours (the peer run).

PureJaxRL is not packaged: clone it (github.com/luchris429/purejaxrl) and point ``--purejaxrl`` at its
``purejaxrl/`` folder (``ppo.py`` and ``wrappers.py``). Its README's CartPole settings are ours
(``configs/ppo/classic-cartpole-balance``). Two adapters, applied here without editing its files:

- gymnax >= 1.0 steps return ``terminated, truncated``; PureJaxRL expects one ``done`` (their ``or``);
- where ``distrax`` is not installed, a 5-line ``Categorical`` (log-softmax logits) stands in;
  ``navix`` (imported by its wrappers, unused for CartPole) is stubbed when missing.

Each seed count is compiled (timed apart), then its first call is timed. Usage::

    python benchmarks/purejaxrl_cartpole.py --purejaxrl ~/purejaxrl/purejaxrl --seeds 1,1024
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import types

import jax
import jax.numpy as jnp

CONFIG = {"LR": 2.5e-4, "NUM_ENVS": 4, "NUM_STEPS": 128, "TOTAL_TIMESTEPS": 5e5, "UPDATE_EPOCHS": 4,
          "NUM_MINIBATCHES": 4, "GAMMA": 0.99, "GAE_LAMBDA": 0.95, "CLIP_EPS": 0.2, "ENT_COEF": 0.01,
          "VF_COEF": 0.5, "MAX_GRAD_NORM": 0.5, "ACTIVATION": "tanh", "ENV_NAME": "CartPole-v1",
          "ANNEAL_LR": True, "DEBUG": False}


class _Categorical:
    """distrax.Categorical's sample, log_prob and entropy."""

    def __init__(self, logits):
        self.logits = jax.nn.log_softmax(logits)

    def sample(self, seed):
        return jax.random.categorical(seed, self.logits)

    def log_prob(self, value):
        return jnp.take_along_axis(self.logits, value[..., None].astype(jnp.int32), axis=-1)[..., 0]

    def entropy(self):
        return -jnp.sum(jnp.exp(self.logits) * self.logits, axis=-1)


class _DoneStep:
    """A gymnax env whose ``step`` returns ``(obs, state, reward, terminated or truncated, info)``."""

    def __init__(self, env):
        self._env = env

    def __getattr__(self, name):
        return getattr(self._env, name)

    def step(self, key, state, action, params=None):
        out = self._env.step(key, state, action, params)
        if len(out) == 5:
            return out
        obs, state, reward, terminated, truncated, info = out
        return obs, state, reward, jnp.logical_or(terminated, truncated), info


def load_make_train(folder: str):
    import gymnax

    if importlib.util.find_spec("distrax") is None:
        sys.modules["distrax"] = types.SimpleNamespace(Categorical=_Categorical)
    if importlib.util.find_spec("navix") is None:
        sys.modules["navix"] = types.ModuleType("navix")
    make = gymnax.make
    gymnax.make = lambda name, **kw: (lambda env, params: (_DoneStep(env), params))(*make(name, **kw))
    sys.path.insert(0, folder)
    from ppo import make_train
    return make_train


def main(argv=None) -> None:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--purejaxrl", required=True, help="PureJaxRL's purejaxrl/ folder (ppo.py, wrappers.py)")
    parser.add_argument("--seeds", default="1,1024", help="comma-separated seed counts (vmapped)")
    args = parser.parse_args(argv)
    make_train = load_make_train(args.purejaxrl)
    updates = int(CONFIG["TOTAL_TIMESTEPS"]) // (CONFIG["NUM_ENVS"] * CONFIG["NUM_STEPS"])
    print(f"# PureJaxRL PPO CartPole-v1, {updates * CONFIG['NUM_ENVS'] * CONFIG['NUM_STEPS']} steps per seed, "
          f"device {jax.devices()[0].device_kind}, jax {jax.__version__}")
    print("| seeds | compile s | train s | env-steps/s (all seeds) | last training return (mean over seeds) |")
    print("|---|---|---|---|---|")
    for seeds in [int(s) for s in args.seeds.split(",")]:
        keys = jax.random.split(jax.random.PRNGKey(30), seeds)
        start = time.perf_counter()
        compiled = jax.jit(jax.vmap(make_train(CONFIG))).lower(keys).compile()
        compile_s = time.perf_counter() - start
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(keys))
        train_s = time.perf_counter() - start
        final = float(out["metrics"]["returned_episode_returns"][:, -1].mean())
        steps = seeds * updates * CONFIG["NUM_ENVS"] * CONFIG["NUM_STEPS"]
        print(f"| {seeds} | {compile_s:.1f} | {train_s:.2f} | {steps / train_s:.3g} | {final:.1f} |", flush=True)


if __name__ == "__main__":
    main()
