"""Agent configs: frozen dataclasses built from dicts, with clear errors for unknown or bad keys."""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

C = TypeVar("C")


class ConfigError(ValueError):
    """An unknown key or a value of the wrong type in an agent config."""


def make_config(cls: type[C], overrides: Mapping[str, Any] | None = None, *, agent: str = "agent") -> C:
    """Builds ``cls`` (a dataclass) from its defaults updated by ``overrides``.

    Raises:
      ConfigError: a key that ``cls`` does not define (listing the valid keys), or a value that cannot
        be converted to the field's annotated type (``null`` only where the annotation allows ``None``).
    """
    overrides = dict(overrides or {})
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ConfigError(f"unknown config key(s) {unknown} for agent {agent!r}; valid keys: {sorted(fields)}")
    values = {}
    defaults = cls()
    hints = typing.get_type_hints(cls)
    for name, value in overrides.items():
        kinds = _field_kinds(hints.get(name), getattr(defaults, name))
        if value is None and type(None) in kinds:
            values[name] = None
            continue
        values[name] = _convert(value, [k for k in kinds if k is not type(None)], name, agent,
                                optional=type(None) in kinds)
    return dataclasses.replace(defaults, **values)


def _field_kinds(hint, default) -> tuple[type, ...]:
    """The types a field accepts: its annotation's (``int | None`` -> ``(int, NoneType)``), else its
    default's."""
    if hint is None or hint is Any:
        return (type(default),)
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return tuple(typing.get_origin(h) or h for h in typing.get_args(hint))
    return (typing.get_origin(hint) or hint,)


def _convert(value, kinds: list[type], name: str, agent: str, optional: bool):
    """``value`` as the first of ``kinds`` it converts to without loss; a ConfigError otherwise."""
    for kind in kinds:
        if kind is bool:
            if isinstance(value, bool):
                return value
        elif kind in (int, float):
            if isinstance(value, bool) or not isinstance(value, int | float | str):
                continue
            try:
                converted = kind(value)
            except (TypeError, ValueError):
                continue
            if kind is int and isinstance(value, float) and not value.is_integer():
                continue
            return converted
        elif kind is tuple:
            if isinstance(value, list | tuple):
                return tuple(value)
        elif isinstance(value, kind):
            return value
    article = {k: "an " if k.__name__[0] in "aeiou" else "a " for k in kinds}
    names = " or ".join(["true or false" if k is bool else article[k] + k.__name__ for k in kinds]
                        + (["null"] if optional else []))
    raise ConfigError(f"config key {name!r} of agent {agent!r} must be {names}, got {value!r}")
