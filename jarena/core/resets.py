"""Auto-reset strategies: where a finished arena's next episode starts, and when it is computed.

An arena names its strategy in ``Arena.auto_reset``; :func:`jarena.auto_reset` and
:func:`jarena.batch_step` follow it. All strategies give the same info layout (the finished step's
reward and flags, the new episode's observation, goal, step and id, ``info.final`` for the old one).

- ``select`` (default): a fresh episode drawn from ``state.rng``, computed for every arena at every step
  and selected where one finished. Best for cheap resets and staggered episodes.
- ``lazy``: the same fresh episodes, computed only in steps where some arena of the batch finished (one
  ``lax.cond`` over the batch). Best for expensive resets and episodes that end together; the cond reads
  its predicate back to the host once per step on GPUs.
- ``repeat``: each arena restarts from its own first episode's initial state, stored by ``reset`` in
  ``state.start``; no reset is computed after the first. This is the auto-reset of Brax's and MuJoCo
  Playground's training wrappers: fastest, at the price of a fixed set of initial states (one per arena)
  and of twice the state memory. ``info.episode`` repeats the first episode's id.
- ``host``: for arenas whose simulator lives outside JAX (:mod:`jarena.arenas.host`: a Gymnasium env, a
  robot). Only where an arena finished, its simulator starts the fresh episode that ``select`` would draw
  from ``state.rng`` (``Dynamics.restart``, one host call for the batch, in steps where some arena
  finished); the others are left alone. The only strategy such arenas accept, and only they accept it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Protocol

import jax

from jarena.core.dynamics import Dynamics
from jarena.core.episodes import episode_of_key, piece_key
from jarena.core.types import ArenaParams, ArenaState, Info

Array = jax.Array


class Arena(Protocol):
    """What a strategy needs of an arena (:class:`jarena.core.arena.Arena`, which sits above this module)."""

    name: str
    dynamics: Dynamics

    def reset(self, key, params: ArenaParams | None = None, episode=None) -> tuple[ArenaState, Info]: ...

    def begin_episode(self, physics, key, episode, params: ArenaParams) -> tuple[ArenaState, Info]: ...


def fresh_episode(arena: Arena, state: ArenaState, params: ArenaParams, done: Array) -> tuple[ArenaState, Info]:
    """A new episode of one arena drawn from its ``rng``."""
    return arena.reset(state.rng.unpack(), params)


def restarted_episode(arena: Arena, state: ArenaState, params: ArenaParams, done: Array
                      ) -> tuple[ArenaState, Info]:
    """The episode :func:`fresh_episode` would draw, started in a host simulator where ``done``."""
    key = state.rng.unpack()
    episode = episode_of_key(key)
    physics = arena.dynamics.restart(state.physics, piece_key(episode, 0), done, params.dynamics)
    return arena.begin_episode(physics, key, episode, params)


def first_episode(arena: Arena, state: ArenaState, params: ArenaParams, done: Array) -> tuple[ArenaState, Info]:
    """The arena's stored first episode (``state.start``), keeping the store for the next restart."""
    if state.start is None:
        raise ValueError(f"arena {arena.name!r} has auto_reset 'repeat' but its state holds no first episode: "
                         "make the state with this arena's reset (or jarena.batch_reset)")
    start_state, start_info = state.start
    return start_state.replace(start=state.start), start_info


@dataclasses.dataclass(frozen=True)
class ResetStrategy:
    """How finished arenas restart.

    Attributes:
      new_episode: ``(arena, state, params, done) -> (state, info)``, one arena's next episode (used where
        ``done``, the bool scalar that says whether its episode ended).
      only_when_done: compute ``new_episode`` for the batch inside a ``lax.cond``, only in steps where
        an arena finished.
      keeps_start: ``Arena.reset`` stores its ``(state, info)`` in ``state.start``.
    """

    new_episode: Callable[[Arena, ArenaState, ArenaParams], tuple[ArenaState, Info]]
    only_when_done: bool = False
    keeps_start: bool = False


RESET_STRATEGIES: dict[str, ResetStrategy] = {
    "select": ResetStrategy(fresh_episode),
    "lazy": ResetStrategy(fresh_episode, only_when_done=True),
    "repeat": ResetStrategy(first_episode, keeps_start=True),
    "host": ResetStrategy(restarted_episode, only_when_done=True),
}


def reset_strategy(name: str) -> ResetStrategy:
    if name not in RESET_STRATEGIES:
        raise ValueError(f"unknown auto_reset {name!r}; choose from {', '.join(RESET_STRATEGIES)}")
    return RESET_STRATEGIES[name]
