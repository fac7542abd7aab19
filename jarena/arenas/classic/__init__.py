"""Classic control arenas in pure JAX, matching Gymnasium's implementations.

Builder ``classic``: ``classic|domain:<domain>,task:<task>[,action:<tools>][,time_limit:N][,wrap:<tasks>]``.
"""

from __future__ import annotations

from typing import Any

from jarena.arenas.assemble import assemble, variants
from jarena.arenas.classic import acrobot, cartpole, mountain_car, pendulum, point_mass
from jarena.arenas.domain import Domain
from jarena.building.builder import register_arena_builder
from jarena.core.arena import Arena

DOMAINS: dict[str, Domain] = {d.name: d for d in [cartpole.DOMAIN, pendulum.DOMAIN, mountain_car.DOMAIN, acrobot.DOMAIN,
                                                  point_mass.DOMAIN]}


def build(domain: str, task: Any = None, action: Any = None, time_limit: int | None = None, wrap: Any = None,
          eval_episodes: int | None = None, val_episodes: int | None = None, auto_reset: str | None = None) -> Arena:
    """Builds a classic arena.

    Args:
      domain: one of ``DOMAINS``.
      task: a task of the domain (default: its first), optionally as a call with keyword arguments.
      action: action tools in front of the domain's control, e.g. ``repeat(2)`` or ``[rescale,repeat(2)]``.
      time_limit: episode length in dynamics steps (default: the domain's, as in Gymnasium).
      wrap: task transforms after the time limit, e.g. ``reward_scale(0.1)`` or a list.
      eval_episodes: size of the evaluation split.
      val_episodes: size of the validation split.
      auto_reset: how finished episodes restart under auto-reset: ``select``, ``lazy`` or ``repeat``
        (each arena replays its first initial state, as Brax and Playground; fastest); default: the
        domain's (see ``jarena.core.resets``).
    """
    return assemble("classic", DOMAINS, domain, task, action, time_limit, wrap, eval_episodes, val_episodes,
                    auto_reset=auto_reset)


register_arena_builder("classic", build, variants=lambda: variants("classic", DOMAINS), tags=("classic",))
