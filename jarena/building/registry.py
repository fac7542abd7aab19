"""A named registry with tags and helpful errors, used for arena builders, agents, tasks and tools."""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable, Iterator
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class RegistryError(KeyError):
    """An unknown or duplicate name in a registry."""

    def __str__(self):  # KeyError quotes its message; show it plainly.
        return str(self.args[0])


@dataclasses.dataclass(frozen=True)
class Entry(Generic[T]):
    name: str
    value: T
    tags: tuple[str, ...] = ()


class Registry(Generic[T]):
    """Maps names to values (builders, factories), each with tags."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}

    def register(self, name: str, value: T, *, tags: tuple[str, ...] = (), overwrite: bool = False) -> T:
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"{self.kind} names must be identifiers, got {name!r}")
        if name in self._entries and not overwrite:
            raise RegistryError(f"{self.kind} {name!r} is already registered; pass overwrite=True to replace it")
        self._entries[name] = Entry(name, value, tuple(tags))
        return value

    def get(self, name: str) -> T:
        return self.entry(name).value

    def entry(self, name: str) -> Entry[T]:
        if name not in self._entries:
            raise RegistryError(unknown_choice(self.kind, name, self.names()))
        return self._entries[name]

    def names(self, tag: str | None = None) -> list[str]:
        return sorted(n for n, e in self._entries.items() if tag is None or tag in e.tags)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[Entry[T]]:
        return iter(self._entries.values())


def unknown_choice(kind: str, name: Any, choices: list[str]) -> str:
    """``unknown <kind> 'x'; valid choices: a, b (did you mean 'a'?)``."""
    close = difflib.get_close_matches(str(name), choices, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown {kind} {name!r}{hint}; valid choices: {', '.join(choices) or '(none registered)'}"


def decorator(registry: Registry, name: str, tags: tuple[str, ...] = ()) -> Callable[[T], T]:
    def wrap(fn):
        registry.register(name, fn, tags=tags)
        return fn
    return wrap


AGENTS: Registry[Callable[..., Any]] = Registry("agent")
"""Agent factories by name, filled by ``jarena_agents.register_agent``. It lives here, below the agents, so
that ``jarena`` (e.g. :func:`jarena.retrieve_config`) can tell a known agent name from a typo without
importing ``jarena_agents``."""
