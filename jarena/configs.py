"""Tuned agent configs: ``retrieve_config(agent, arena, name="default")`` reads ``configs/``.

Layout: ``configs/<agent>/<arena-name>/<name>.yaml`` for a tuned pair, falling back to
``configs/<agent>/<name>.yaml`` for the agent's defaults. ``<arena-name>`` is ``arena.name``
(``classic-cartpole-balance``). The folder is searched in ``$JARENA_CONFIGS`` (if set), the source
checkout's ``configs/``, and the installed package's ``jarena/_configs``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from jarena.building.registry import AGENTS, RegistryError, unknown_choice


def config_roots() -> list[Path]:
    roots = []
    if os.environ.get("JARENA_CONFIGS"):
        roots.append(Path(os.environ["JARENA_CONFIGS"]))
    here = Path(__file__).resolve().parent
    roots += [here.parent / "configs", here / "_configs"]
    return [r for r in roots if r.is_dir()]


def _arena_name(arena: Any) -> str:
    if isinstance(arena, str):
        if "|" in arena:
            from jarena.building import build_arena

            return build_arena(arena).name
        return arena
    return arena.name


def _agent_name(agent: Any) -> str:
    return agent if isinstance(agent, str) else agent.name


def _check_known(agent_name: str, roots: list[Path]) -> None:
    """Raises the agent registry's ``RegistryError`` for a name that is neither a registered agent
    (:data:`jarena.building.registry.AGENTS`) nor has a configs folder."""
    if agent_name in AGENTS or any((root / agent_name).is_dir() for root in roots):
        return
    hint = "" if AGENTS.names() else " (agents register when jarena_agents is imported)"
    raise RegistryError(unknown_choice("agent", agent_name, AGENTS.names()) + hint)


def retrieve_config(agent: Any, arena: Any = None, name: str = "default") -> dict[str, Any]:
    """The config ``name`` for ``agent`` (a name or Agent) on ``arena`` (an Arena, name or string).

    Returns an empty dict when the agent has no configs at all (it then runs on its built-in
    defaults); raises ``FileNotFoundError`` listing what exists when ``name`` is not found, and the
    agent registry's ``RegistryError`` (a ``KeyError``) for an agent name that is neither registered
    nor has configs.
    """
    agent_name = _agent_name(agent)
    if isinstance(agent, str):
        _check_known(agent_name, config_roots())
    arena_name = None if arena is None else _arena_name(arena)
    candidates, available = [], []
    for root in config_roots():
        if arena_name is not None:
            candidates.append(root / agent_name / arena_name / f"{name}.yaml")
        candidates.append(root / agent_name / f"{name}.yaml")
        if (root / agent_name).is_dir():
            available += [str(p.relative_to(root)) for p in sorted((root / agent_name).rglob("*.yaml"))]
    for path in candidates:
        if path.is_file():
            with open(path) as f:
                loaded = yaml.safe_load(f) or {}
            if not isinstance(loaded, dict):
                raise ValueError(f"config {path} must hold a mapping of keys to values, got {type(loaded).__name__}")
            return loaded
    if not available and name == "default":
        return {}
    raise FileNotFoundError(f"no config {name!r} for agent {agent_name!r}" +
                            (f" on arena {arena_name!r}" if arena_name else "") +
                            f"; available: {', '.join(available) or 'none'}")
