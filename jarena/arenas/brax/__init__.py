"""Brax's environments (``brax.envs``, Brax 0.14.2) as jarena arenas, Brax's reward as the default task.

Builder ``brax``::

    brax|env:<env>[(<option>=<value>,...)][,backend:<backend>][,action:<tools>][,time_limit:N][,wrap:<tasks>]

- ``env``: one of :data:`ENVS`; keyword arguments of the env's constructor go in parentheses, as
  ``brax|env:ant(ctrl_cost_weight=0.1,healthy_z_range=[0.3,1.0])`` (lists become tuples). They are
  build-time options (static, as Brax's); an unknown one is an error that lists the env's options.
- ``backend``: Brax's physics pipeline, one of :data:`BACKENDS` (default ``generalized``, Brax's own).
- ``action``, ``wrap``: jarena action tools and task transforms on top (``action:repeat(2)``,
  ``wrap:reward_scale(0.1)``).
- ``time_limit``: episode length in Brax env steps (default 1000, Brax's ``episode_length``); with
  ``action:repeat(k)`` an episode has ``1000 / k`` agent steps, as with Brax's ``action_repeat``.

The arena steps Brax's env itself (see :mod:`jarena.arenas.brax.env`): same key, same actions, same
observations, rewards and ``done`` as ``brax.envs.get_environment(env, backend=...)``. Params are
:class:`jarena.arenas.brax.env.BraxParams` (mass and friction scales). Brax is imported only when an
arena is built, so ``import jarena`` and listing arenas stay light.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any

from jarena.arenas.assemble import assemble
from jarena.arenas.domain import Domain
from jarena.building.builder import register_arena_builder
from jarena.building.grammar import ArenaStringError, Call
from jarena.building.registry import unknown_choice
from jarena.core.arena import Arena

#: Env name (as in ``brax.envs``) -> its class, ``module:Class``. Static: listing arenas imports nothing.
ENVS: dict[str, str] = {
    "ant": "brax.envs.ant:Ant",
    "halfcheetah": "brax.envs.half_cheetah:Halfcheetah",
    "hopper": "brax.envs.hopper:Hopper",
    "humanoid": "brax.envs.humanoid:Humanoid",
    "walker2d": "brax.envs.walker2d:Walker2d",
    "reacher": "brax.envs.reacher:Reacher",
    "pusher": "brax.envs.pusher:Pusher",
    "inverted_pendulum": "brax.envs.inverted_pendulum:InvertedPendulum",
    "inverted_double_pendulum": "brax.envs.inverted_double_pendulum:InvertedDoublePendulum",
}

#: Brax's physics pipelines. Brax 0.14.2 builds and steps every env above on each of them (some envs
#: change their timestep and ``n_frames`` on ``spring`` and ``positional``, as Brax does).
BACKENDS: tuple[str, ...] = ("generalized", "positional", "spring", "mjx")
DEFAULT_BACKEND = "generalized"

#: Brax's default ``episode_length`` (``brax.envs.create``, ``brax.envs.training.wrap``).
TIME_LIMIT = 1000

_TAGS = ("brax", "mujoco", "benchmark")


def _env_call(env: Any) -> tuple[str, dict[str, Any]]:
    """``(name, options)`` from ``env:name`` or ``env:name(option=value,...)``."""
    call = Call(env) if isinstance(env, str) else env
    if not isinstance(call, Call):
        raise ArenaStringError(f"env must be a name or a call such as ant(ctrl_cost_weight=0.1), got {env!r}")
    if call.name not in ENVS:
        raise ArenaStringError(unknown_choice("brax env", call.name, list(ENVS)))
    if call.args:
        raise ArenaStringError(f"options of brax env {call.name!r} must be given by keyword, as "
                               f"{call.name}(option=value); got positional {list(call.args)}")
    return call.name, {k: tuple(v) if isinstance(v, list) else v for k, v in call.kwargs}


def build(env: Any, backend: str = DEFAULT_BACKEND, action: Any = None, time_limit: int | None = None,
          wrap: Any = None, eval_episodes: int | None = None, val_episodes: int | None = None,
          auto_reset: str | None = None) -> Arena:
    """Builds Brax env ``env`` as an arena.

    Args:
      env: one of ``ENVS``, optionally with constructor options: ``ant(ctrl_cost_weight=0.1)``.
      backend: one of ``BACKENDS``.
      action: action tools in front of Brax's action, e.g. ``repeat(2)``.
      time_limit: episode length in Brax env steps (default 1000).
      wrap: task transforms after the time limit, e.g. ``reward_scale(0.1)``.
      eval_episodes: size of the evaluation split.
      val_episodes: size of the validation split.
      auto_reset: how finished episodes restart under auto-reset: ``select``, ``lazy`` or ``repeat``
        (each arena replays its first initial state, as Brax and Playground; fastest); default: the
        domain's (see ``jarena.core.resets``).
    """
    name, options = _env_call(env)
    if backend not in BACKENDS:
        raise ArenaStringError(unknown_choice(f"backend for brax env {name!r}:", backend, list(BACKENDS)))
    brax_env = importlib.import_module("jarena.arenas.brax.env")
    valid = brax_env.env_options(ENVS[name])
    for key in options:
        if key not in valid:
            hint = "; give the backend as its own key, brax|env:...,backend:mjx" if key == "backend" else ""
            raise ArenaStringError(unknown_choice(f"option of brax env {name!r}:", key, valid) + hint)
    try:
        env_obj = brax_env.make_env(ENVS[name], backend, **options)
    except (TypeError, ValueError, NotImplementedError) as e:
        raise ArenaStringError(f"brax env {name!r} rejects options {options}: {type(e).__name__}: {e}") from None
    brax_env.check_action_range(name, env_obj)
    label = f"brax-{name}-{backend}"
    domain = Domain(name=name, dynamics=lambda: brax_env.brax_dynamics(env_obj, name=label),
                    sensor=lambda: brax_env.sensor(label), tasks={"brax": brax_env.brax_task},
                    time_limit=TIME_LIMIT)
    arena = assemble("brax", {name: domain}, name, None, action, time_limit, wrap, eval_episodes, val_episodes,
                     auto_reset=auto_reset)
    return dataclasses.replace(arena, name=label)


def variants() -> list[tuple[str, tuple[str, ...]]]:
    """Every env on Brax's default backend, tagged ``brax``, ``mujoco`` and ``benchmark``."""
    return [(f"brax|env:{name}", _TAGS) for name in ENVS]


register_arena_builder("brax", build, variants=variants, tags=("brax", "mujoco"))
