"""Building arenas from strings: ``build_arena("classic|domain:cartpole,task:balance,action:repeat(2)")``.

A builder is a function of keyword arguments returning an :class:`~jarena.core.arena.Arena`; its
parameter names are the keys the string may use. Register one with :func:`register_arena_builder`,
together with the variants it can build (for :func:`list_arenas`) and tags (``benchmark``...).
Action tools and task transforms named in strings come from their own registries (:data:`TOOLS`,
:data:`TASKS`), which users extend with :func:`register_tool` and :func:`register_task`.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable, Iterable
from typing import Any

from jarena.building.grammar import ArenaString, ArenaStringError, Call, format_value, parse_arena_string
from jarena.building.registry import Registry, unknown_choice
from jarena.core.arena import Arena
from jarena.core.chain import chain
from jarena.core.task import Task
from jarena.core.tool import ActionTool


@dataclasses.dataclass(frozen=True)
class ArenaBuilder:
    """A registered builder.

    Attributes:
      fn: ``(**pairs) -> Arena``.
      variants: ``() -> iterable of (arena string, tags)`` that this builder can build.
    """

    name: str
    fn: Callable[..., Arena]
    variants: Callable[[], Iterable[tuple[str, tuple[str, ...]]]]

    @property
    def keys(self) -> list[str]:
        params = inspect.signature(self.fn).parameters.values()
        return [p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]

    @property
    def required_keys(self) -> list[str]:
        params = inspect.signature(self.fn).parameters.values()
        return [p.name for p in params
                if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]


BUILDERS: Registry[ArenaBuilder] = Registry("arena builder")
TOOLS: Registry[Callable[..., ActionTool]] = Registry("action tool")
TASKS: Registry[Callable[..., Task]] = Registry("task transform")


def register_arena_builder(name: str, fn: Callable[..., Arena], *,
                           variants: Callable[[], Iterable[tuple[str, tuple[str, ...]]]] | None = None,
                           tags: tuple[str, ...] = (), overwrite: bool = False) -> Callable[..., Arena]:
    """Registers ``fn`` as the builder ``name`` (the part of an arena string before ``|``).

    Args:
      name: builder name.
      fn: ``(**pairs) -> Arena``; its keyword parameters are the keys the string may use.
      variants: ``() -> [(arena_string, tags), ...]`` listed by :func:`list_arenas`; default: the bare
        builder name.
      tags: tags of the builder itself.
      overwrite: replace an existing builder of the same name.
    """
    variants = variants or (lambda: [(name, tuple(tags))])
    BUILDERS.register(name, ArenaBuilder(name, fn, variants), tags=tags, overwrite=overwrite)
    return fn


def register_tool(name: str, factory: Callable[..., ActionTool], overwrite: bool = False):
    """Makes ``factory`` usable in arena strings as ``action:name(args)``."""
    return TOOLS.register(name, factory, overwrite=overwrite)


def register_task(name: str, factory: Callable[..., Task], overwrite: bool = False):
    """Makes ``factory`` usable in arena strings as ``wrap:name(args)``."""
    return TASKS.register(name, factory, overwrite=overwrite)


def build_arena(arena_string: str) -> Arena:
    """Builds an arena from ``builder|key:value,...`` (see :mod:`jarena.building.grammar`).

    Raises:
      ArenaStringError: malformed string, unknown builder, unknown or missing key, invalid value.
    """
    parsed = parse_arena_string(arena_string)
    if parsed.builder not in BUILDERS:
        raise ArenaStringError(unknown_choice("arena builder", parsed.builder, BUILDERS.names())
                               + f"\n  in arena string {arena_string!r}")
    builder = BUILDERS.get(parsed.builder)
    keys = builder.keys
    for key in parsed.pairs:
        if key not in keys:
            raise ArenaStringError(unknown_choice(f"key for builder {parsed.builder!r}:", key, keys)
                                   + f"\n  in arena string {arena_string!r}")
    missing = [k for k in builder.required_keys if k not in parsed.pairs]
    if missing:
        raise ArenaStringError(f"builder {parsed.builder!r} needs key(s) {missing}; valid keys: {keys}"
                               f"\n  in arena string {arena_string!r}")
    try:
        arena = builder.fn(**parsed.pairs)
    except ArenaStringError as e:
        raise ArenaStringError(f"{e}\n  in arena string {arena_string!r}") from None
    if not isinstance(arena, Arena):
        raise TypeError(f"builder {parsed.builder!r} returned {type(arena).__name__}, not an Arena")
    return dataclasses.replace(arena, build_string=str(parsed))


def list_arenas(tag: str | None = None) -> list[str]:
    """Arena strings that registered builders can build, optionally only those tagged ``tag``."""
    found = []
    for entry in BUILDERS:
        for string, tags in entry.value.variants():
            if tag is None or tag in tags:
                found.append(string)
    return sorted(found)


def arena_tags(arena_string: str) -> tuple[str, ...]:
    """Tags of a listed arena string (empty if not listed)."""
    parsed = parse_arena_string(arena_string)
    if parsed.builder not in BUILDERS:
        return ()
    canonical = str(parsed)
    for string, tags in BUILDERS.get(parsed.builder).variants():
        if string == canonical:
            return tuple(tags)
    return ()


def _instantiate(registry: Registry, value: Any, what: str):
    """Builds a transform from a parsed value: a name, a :class:`Call`, or a list (chained)."""
    if isinstance(value, list):
        if not value:
            raise ArenaStringError(f"empty list given for {what}")
        parts = [_instantiate(registry, v, what) for v in value]
        return chain(*parts) if len(parts) > 1 else parts[0]
    if isinstance(value, str):
        value = Call(value)
    if not isinstance(value, Call):
        raise ArenaStringError(f"invalid {what} {format_value(value)!r}: expected a name, a call such as "
                               f"{registry.names()[0] if registry.names() else 'name'}(...), or a list of them; "
                               f"valid names: {', '.join(registry.names())}")
    if value.name not in registry:
        raise ArenaStringError(unknown_choice(what, value.name, registry.names()))
    factory = registry.get(value.name)
    try:
        inspect.signature(factory).bind(*value.args, **dict(value.kwargs))
    except TypeError as e:
        raise ArenaStringError(f"bad arguments in {value}: {e}; signature: "
                               f"{value.name}{inspect.signature(factory)}") from None
    try:
        return factory(*value.args, **dict(value.kwargs))
    except (ValueError, TypeError) as e:
        raise ArenaStringError(f"invalid {what} {value}: {e}") from None


def make_tool(value: Any) -> ActionTool:
    """An action tool from a parsed string value (``repeat(2)``, ``[rescale(-1,1),repeat(2)]``)."""
    return _instantiate(TOOLS, value, "action tool")


def make_task(value: Any) -> Task:
    """A task transform from a parsed string value (``reward_scale(0.1)``, ``[...]``)."""
    return _instantiate(TASKS, value, "task transform")


__all__ = ["ArenaBuilder", "ArenaString", "ArenaStringError", "BUILDERS", "TASKS", "TOOLS", "arena_tags",
           "build_arena", "list_arenas", "make_task", "make_tool", "register_arena_builder", "register_task",
           "register_tool"]
