"""Assembling an arena from a domain, a task name and optional string-given transforms.

Shared by builders whose arenas are ``domain x task`` (``classic``, and suites such as ``dmc``).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from typing import Any

from jarena.arenas.domain import Domain
from jarena.building.builder import make_task, make_tool
from jarena.building.grammar import ArenaStringError, Call
from jarena.building.registry import unknown_choice
from jarena.core.arena import Arena
from jarena.core.chain import chain
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.resets import reset_strategy
from jarena.tasks.time_limit import time_limit as time_limit_task


def assemble(builder: str, domains: Mapping[str, Domain], domain: str, task: Any = None, action: Any = None,
             time_limit: int | None = None, wrap: Any = None, eval_episodes: int | None = None,
             val_episodes: int | None = None, auto_reset: str | None = None,
             sensor: Callable[[Sensor, Dynamics], Sensor] | None = None) -> Arena:
    """Builds ``domain``'s arena for ``task`` (a name or a call with keyword arguments).

    The task chain is ``chain(base task, time_limit, *wrap)``; the tool chain is the domain's default
    tool, then ``action`` (a tool, call or list of them) in front of it. ``auto_reset`` overrides the
    domain's reset strategy (one of ``jarena.core.resets.RESET_STRATEGIES``). ``sensor``, if given, maps the
    task's sensor and the dynamics to the arena's sensor (e.g. adds cameras).
    """
    if domain not in domains:
        raise ArenaStringError(unknown_choice(f"{builder} domain", domain, sorted(domains)))
    dom = domains[domain]
    task = dom.default_task if task is None else task
    task_call = Call(task) if isinstance(task, str) else task
    if not isinstance(task_call, Call):
        raise ArenaStringError(f"task must be a name or a call such as name(key=value), got {task!r}")
    if task_call.name not in dom.tasks:
        raise ArenaStringError(unknown_choice(f"task of {builder} domain {domain!r}:", task_call.name,
                                              list(dom.tasks)))
    factory = dom.tasks[task_call.name]
    try:
        inspect.signature(factory).bind(*task_call.args, **dict(task_call.kwargs))
        base = factory(*task_call.args, **dict(task_call.kwargs))
    except TypeError as e:
        raise ArenaStringError(f"bad arguments in task {task_call}: {e}; signature: "
                               f"{task_call.name}{inspect.signature(factory)}") from None

    if auto_reset is not None:
        try:
            reset_strategy(auto_reset)
        except ValueError as e:
            raise ArenaStringError(str(e)) from None

    tasks = [base]
    limit = dom.time_limit if time_limit is None else time_limit
    if limit is not None:
        if not isinstance(limit, int) or limit < 1:
            raise ArenaStringError(f"time_limit must be a positive integer, got {limit!r}")
        tasks.append(time_limit_task(limit))
    if wrap is not None:
        tasks.append(make_task(wrap))

    tools = [] if action is None else [make_tool(action)]
    if dom.tool is not None:
        tools.append(dom.tool())

    dynamics = dom.dynamics_for(task_call.name)
    extra = split_sizes(eval_episodes, val_episodes)
    observer = dom.sensor_for(task_call.name)
    if sensor is not None:
        observer = sensor(observer, dynamics)
    arena = Arena(dynamics=dynamics, sensor=observer, task=chain(*tasks),
                  tool=chain(*tools) if tools else Arena.tool, name=f"{builder}-{domain}-{task_call.name}",
                  auto_reset=dom.auto_reset if auto_reset is None else auto_reset, **extra)
    try:
        _ = arena.action_spec  # tools check the spec they drive here, at build time
    except (TypeError, ValueError) as e:
        raise ArenaStringError(f"action tools do not fit {builder} domain {domain!r} "
                               f"(control {dynamics.control_spec!r}): {e}") from None
    return arena


def split_sizes(eval_episodes: int | None, val_episodes: int | None) -> dict[str, int]:
    """:class:`Arena` keyword arguments for the eval and validation split sizes an arena string gives (each left
    out when not given, so that the arena's defaults hold)."""
    sizes = {}
    if eval_episodes is not None:
        sizes["num_eval_episodes"] = int(eval_episodes)
    if val_episodes is not None:
        sizes["num_val_episodes"] = int(val_episodes)
    return sizes


def variants(builder: str, domains: Mapping[str, Domain]) -> list[tuple[str, tuple[str, ...]]]:
    """``(arena string, tags)`` for every domain x task."""
    out = []
    for name, dom in domains.items():
        for task in dom.tasks:
            out.append((f"{builder}|domain:{name},task:{task}", (builder,) + tuple(dom.tags.get(task, ()))))
    return out
