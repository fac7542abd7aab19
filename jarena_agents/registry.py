"""The agent registry: ``build_agent(name, config)`` and ``register_agent``."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from jarena.building import registry
from jarena.building.registry import Registry
from jarena.core.agent import Agent

# The registry object lives in jarena (a layer below), where jarena.retrieve_config looks names up.
AGENTS: Registry[Callable[[Mapping[str, Any]], Agent]] = registry.AGENTS


def register_agent(name: str, factory: Callable[[Mapping[str, Any]], Agent], *, tags: tuple[str, ...] = (),
                   overwrite: bool = False):
    """Registers ``factory(config: dict) -> Agent`` under ``name`` (usable by ``build_agent`` and the CLI)."""
    return AGENTS.register(name, factory, tags=tags, overwrite=overwrite)


def build_agent(name: str, config: Mapping[str, Any] | None = None) -> Agent:
    """Builds the agent ``name`` from ``config`` (a dict; unknown keys raise ``ConfigError``)."""
    return AGENTS.get(name)(dict(config or {}))


def list_agents(tag: str | None = None) -> list[str]:
    return AGENTS.names(tag)
