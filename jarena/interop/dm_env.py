"""A jarena arena as a ``dm_env.Environment`` (DeepMind's environment API, which dm_control and Acme use).

``reset()`` gives a ``FIRST`` time step; ``step(action)`` gives ``MID`` steps and a ``LAST`` one when the
episode ends, with discount 0 where it terminated and 1 where the time limit truncated it (dm_env's
convention); the ``step`` after a ``LAST`` starts a new episode, as dm_env asks. Rewards and discounts are
float64 scalars (the default ``reward_spec`` and ``discount_spec``, as dm_control's); observations are the
arena's observation dict. Episodes draw their keys from a numpy generator seeded by ``seed``, or play fixed
jarena episodes (``episodes=arena.episodes("eval")``), one per reset in order, cycling.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import dm_env
import jax
import numpy as np
from dm_env import specs as dm_specs

from jarena.core import spec as specs
from jarena.core.arena import Arena
from jarena.core.types import ArenaParams, Info
from jarena.interop.host_values import SEED_RANGE, action_dtypes, cast_action


def _box(spec: specs.Box, name: str) -> dm_specs.Array:
    if spec.bounded:
        return dm_specs.BoundedArray(spec.shape, spec.dtype, spec.low.astype(spec.dtype), spec.high.astype(spec.dtype),
                                     name=name)
    return dm_specs.Array(spec.shape, spec.dtype, name=name)


def _discrete(spec: specs.Discrete, name: str) -> dm_specs.DiscreteArray:
    return dm_specs.DiscreteArray(int(spec.n), dtype=spec.dtype, name=name)


def _dict(spec: specs.Dict, name: str) -> dict[str, Any]:
    return {k: array_spec(v, k) for k, v in spec.spaces.items()}


def _tuple(spec: specs.Tuple, name: str) -> tuple:
    return tuple(array_spec(v, f"{name}_{i}") for i, v in enumerate(spec.spaces))


#: How each jarena spec type becomes a dm_env spec (nests become dicts and tuples of specs).
SPECS: dict[type, Callable[[Any, str], Any]] = {specs.Box: _box, specs.Discrete: _discrete, specs.Dict: _dict,
                                                specs.Tuple: _tuple}


def array_spec(spec: specs.Spec, name: str = "") -> Any:
    """The dm_env spec of a jarena spec (:data:`SPECS`)."""
    convert = SPECS.get(type(spec))
    if convert is None:
        raise TypeError(f"no dm_env spec for spec {spec!r}; convertible: {', '.join(t.__name__ for t in SPECS)}")
    return convert(spec, name)


class ArenaDmEnv(dm_env.Environment):
    """One jarena arena as a ``dm_env.Environment``; see the module docstring.

    Args:
      arena: the arena (its time limit ends episodes as truncations).
      params: arena params (default: ``arena.default_params()``).
      seed: seeds the keys of the episodes (without ``episodes``).
      episodes: fixed jarena episode ids to play, in order (cycling), instead of seeded ones.
    """

    def __init__(self, arena: Arena, *, params: ArenaParams | None = None, seed: int = 0,
                 episodes: Sequence[int] | None = None):
        self.arena, self.params = arena, arena.default_params() if params is None else params
        self._episodes = None if episodes is None else [int(e) for e in episodes]
        if self._episodes is not None and not self._episodes:
            raise ValueError("episodes must name at least one episode id (or be None for seeded episodes)")
        self._rng, self._count = np.random.default_rng(seed), 0
        self._observation_spec = array_spec(arena.observation_spec)
        self._action_spec = array_spec(arena.action_spec, "action")
        self._action_dtypes = action_dtypes(arena)
        self._reset = jax.jit(arena.reset)
        self._step = jax.jit(arena.step)
        self._state, self._ended = None, True

    def reset(self) -> dm_env.TimeStep:
        episode = None
        if self._episodes is not None:
            episode = self._episodes[self._count % len(self._episodes)]
        key = jax.random.key(int(self._rng.integers(SEED_RANGE)))
        self._count += 1
        self._state, info = self._reset(key, self.params, episode)
        info = jax.device_get(info)
        self._ended = False
        return dm_env.restart(self._observation(info))

    def step(self, action) -> dm_env.TimeStep:
        if self._ended:  # dm_env: the step after the last one (or the first call) starts an episode
            return self.reset()
        self._state, info = self._step(self._state, cast_action(action, self._action_dtypes), self.params)
        info = jax.device_get(info)  # one transfer of everything the step returns
        observation, reward = self._observation(info), np.float64(info.reward)
        if bool(info.terminated):
            self._ended = True
            return dm_env.termination(reward, observation)
        if bool(info.truncated):
            self._ended = True
            return dm_env.truncation(reward, observation)
        return dm_env.transition(reward, observation)

    def observation_spec(self):
        return self._observation_spec

    def action_spec(self):
        return self._action_spec

    @staticmethod
    def _observation(info: Info) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in info.observation.items()}


def to_dm_env(arena: Arena, **options) -> ArenaDmEnv:
    """``arena`` as a ``dm_env.Environment`` (options: :class:`ArenaDmEnv`'s)."""
    return ArenaDmEnv(arena, **options)
