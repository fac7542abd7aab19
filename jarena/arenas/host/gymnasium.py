"""Gymnasium environments as host arenas: :func:`from_gymnasium` and the ``gym`` builder.

Any ``gymnasium.Env`` (a registered id, or a function that makes one: a PyBullet or Atari env, a simulator
behind a socket, a robot's driver) becomes an arena whose steps run on the host, batched through Gymnasium's
vector envs (``SyncVectorEnv``, or ``AsyncVectorEnv`` with ``vectorization="async"``: one worker process per
simulator). Its specs come from the env's spaces, jarena episode ``i`` resets its simulator with seed
:func:`~jarena.arenas.host.pieces.episode_seed` ``(i)`` (so ``arena.episodes("eval")`` is as fixed as
anywhere), and it returns the same :class:`~jarena.core.types.Info` as every arena (the terminal observation in
``info.final``). Action tools and task transforms compose on top as on any arena.

Spaces: observations ``Box`` (float ones as float32, integer ones as int32, ``uint8`` images kept),
``Discrete`` and a flat ``Dict`` of those; a single array is the observation ``{"state": x}`` (an image,
``uint8`` of rank 3: ``{"pixels": x}``). Actions ``Box`` (float32) or ``Discrete``.

Builder ``gym``::

    gym|id:<env id>[(<kwarg>=<value>,...)][,vectorization:sync|async][,max_batches:N][,action:<tools>]
       [,time_limit:N][,wrap:<tasks>]

with ids that hold ``/`` or ``:`` quoted (``gym|id:"ALE/Pong-v5"``). The env's own time limit
(``max_episode_steps``) truncates its episodes, and is the arena's ``max_episode_steps``.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import re
from collections.abc import Callable
from typing import Any

import numpy as np

from jarena.arenas.assemble import assemble
from jarena.arenas.domain import Domain
from jarena.arenas.host.pieces import host_dynamics, host_sensor, host_task
from jarena.arenas.host.pool import EnvPool
from jarena.building.builder import register_arena_builder
from jarena.building.grammar import ArenaStringError, Call
from jarena.building.registry import unknown_choice
from jarena.core import spec as specs
from jarena.core.arena import Arena

VECTORIZATIONS = ("sync", "async")
SPACES = ("Box", "Discrete", "Dict")

#: Listed by ``jarena list``: Gymnasium's classic control envs (its MuJoCo ones need its ``mujoco`` extra).
LISTED = ("CartPole-v1", "Pendulum-v1", "MountainCar-v0", "MountainCarContinuous-v0", "Acrobot-v1")


def _gymnasium():
    try:
        return importlib.import_module("gymnasium")
    except ImportError:
        raise ImportError("host arenas of Gymnasium envs need gymnasium: pip install 'jarena[gymnasium]'") from None


def _array_spec(space: Any, what: str) -> specs.Spec:
    spaces = _gymnasium().spaces
    if isinstance(space, spaces.Discrete):
        if int(space.start) != 0:
            raise TypeError(f"{what}: Discrete spaces must start at 0, got start={space.start}")
        return specs.Discrete(int(space.n))
    if isinstance(space, spaces.Box):
        dtype = np.dtype(space.dtype)
        dtype = (np.uint8 if dtype == np.uint8 else np.float32 if dtype.kind == "f"
                 else np.int32 if dtype.kind in "iu" else None)
        if dtype is None:
            raise TypeError(f"{what}: Box of dtype {space.dtype} is not supported (floats, integers or uint8)")
        return specs.Box(space.low, space.high, space.shape, dtype)
    raise TypeError(f"{what}: {type(space).__name__} spaces are not supported; supported: {', '.join(SPACES)} "
                    "(a flat Dict of Box and Discrete for observations)")


def observation_spec(space: Any) -> tuple[specs.Dict, str | None]:
    """``(jarena Dict spec, key)`` of a Gymnasium observation space; ``key`` names the single array of a
    non-dict space (``state``, or ``pixels`` for a ``uint8`` image), ``None`` for a ``Dict`` space."""
    if isinstance(space, _gymnasium().spaces.Dict):
        return specs.Dict({k: _array_spec(s, f"observation {k!r}") for k, s in space.spaces.items()}), None
    spec = _array_spec(space, "observation")
    key = "pixels" if spec.dtype == np.uint8 and len(spec.shape) == 3 else "state"
    return specs.Dict({key: spec}), key


def action_spec(space: Any) -> specs.Spec:
    """The jarena spec of a Gymnasium action space (``Box``, float32, or ``Discrete``)."""
    return _array_spec(space, "action")


def _observer(spec: specs.Dict, key: str | None) -> Callable[[Any], dict[str, np.ndarray]]:
    def observe(observation):
        observation = {key: observation} if key is not None else observation
        return {k: np.asarray(observation[k], s.dtype) for k, s in spec.spaces.items()}
    return observe


def _vector_env(factory: Callable[[], Any], vectorization: str, size: int):
    vector = _gymnasium().vector
    disabled = vector.AutoresetMode.DISABLED
    if vectorization == "sync":
        return vector.SyncVectorEnv([factory] * size, autoreset_mode=disabled)
    # spawned workers: forking a process that runs JAX's threads can deadlock
    return vector.AsyncVectorEnv([factory] * size, autoreset_mode=disabled, context="spawn")


def _name(env_id: str) -> str:
    return "gym-" + re.sub(r"[^a-z0-9]+", "-", env_id.lower()).strip("-")


def from_gymnasium(env: str | Callable[[], Any], *, vectorization: str = "sync", max_batches: int = 4,
                   name: str | None = None, time_limit: int | None = None, action: Any = None, wrap: Any = None,
                   eval_episodes: int | None = None, val_episodes: int | None = None, **kwargs) -> Arena:
    """A Gymnasium env as a host arena (see the module docstring).

    Args:
      env: a registered id (``"CartPole-v1"``), made with ``gymnasium.make(env, **kwargs)``, or a function of
        no arguments that returns a fresh ``gymnasium.Env`` (one per simulator).
      vectorization: ``sync`` (simulators stepped in turn in this process) or ``async`` (one worker process
        each, stepped in parallel: for slow simulators).
      max_batches: how many batches of simulators (one per ``batch_reset``) stay open at once; a training run
        with validation needs 2, and the least recently used batch is closed beyond this.
      name: the arena's name (default from the id: ``gym-cartpole-v1``).
      time_limit: a jarena time limit in steps, as for every builder.
      action: action tools, as for every builder.
      wrap: task transforms, as for every builder.
      eval_episodes: size of the evaluation split, as for every builder.
      val_episodes: size of the validation split, as for every builder.
      kwargs: keyword arguments of ``gymnasium.make``.

    The batch size is the arena batch's, as for any arena (``batch_reset(arena, key, B)``).
    """
    if vectorization not in VECTORIZATIONS:
        raise ValueError(unknown_choice("vectorization", vectorization, list(VECTORIZATIONS)))
    gym = _gymnasium()
    if isinstance(env, str):
        env_id = env
        try:
            gym.spec(env_id)
        except gym.error.Error as e:
            raise ValueError(f"unknown Gymnasium env id {env_id!r}: {e}") from None
        factory = functools.partial(gym.make, env_id, **kwargs)
    elif callable(env):
        if kwargs:
            raise TypeError(f"keyword arguments {sorted(kwargs)} go to gymnasium.make and need an env id, not a "
                            "factory; give them to the factory")
        env_id, factory = None, env
    else:
        raise TypeError(f"env must be a Gymnasium id or a function that makes an env, got {env!r}")
    probe = factory()
    try:
        obs_spec, key = observation_spec(probe.observation_space)
        control = action_spec(probe.action_space)
        spec = getattr(probe, "spec", None)
        horizon = getattr(spec, "max_episode_steps", None)
        action_dtype = probe.action_space.dtype
        label = name or (_name(env_id) if env_id else _name(type(probe.unwrapped).__name__))
    finally:
        probe.close()
    cast = ((lambda a: np.asarray(a, np.int64)) if isinstance(control, specs.Discrete)
            else (lambda a: np.asarray(a, action_dtype)))
    pool = EnvPool(functools.partial(_vector_env, factory, vectorization), _observer(obs_spec, key), cast,
                   max_batches=max_batches, name=label)
    domain = Domain(name=label, dynamics=lambda: host_dynamics(pool, obs_spec, control, name=label),
                    sensor=lambda: host_sensor(obs_spec, name=label),
                    tasks={"host": lambda: host_task(horizon)}, auto_reset="host")
    arena = assemble("gym", {label: domain}, label, None, action, time_limit, wrap, eval_episodes, val_episodes)
    return dataclasses.replace(arena, name=label)


def build(id: Any, vectorization: str = "sync", max_batches: int = 4, action: Any = None,  # noqa: A002
          time_limit: int | None = None, wrap: Any = None, eval_episodes: int | None = None,
          val_episodes: int | None = None) -> Arena:
    """Builds the Gymnasium env ``id`` (with ``gymnasium.make`` keyword arguments in parentheses:
    ``Pendulum-v1(g=9.81)``) as a host arena; see :func:`from_gymnasium`."""
    call = Call(id) if isinstance(id, str) else id
    if not isinstance(call, Call) or call.args:
        raise ArenaStringError(f"id must be a Gymnasium env id, optionally with keyword arguments of "
                               f"gymnasium.make as Pendulum-v1(g=9.81), got {id!r}")
    if vectorization not in VECTORIZATIONS:
        raise ArenaStringError(unknown_choice("vectorization", vectorization, list(VECTORIZATIONS)))
    try:
        return from_gymnasium(call.name, vectorization=vectorization, max_batches=int(max_batches), action=action,
                              time_limit=time_limit, wrap=wrap, eval_episodes=eval_episodes,
                              val_episodes=val_episodes, **dict(call.kwargs))
    except (ValueError, TypeError) as e:
        raise ArenaStringError(f"gym|id:{call.name}: {e}") from None


register_arena_builder("gym", build, variants=lambda: [(f"gym|id:{i}", ("gym", "host")) for i in LISTED],
                       tags=("gym", "host"))
