"""Agent configs: frozen dataclasses built from dicts, with clear errors for unknown or bad keys."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

C = TypeVar("C")


class ConfigError(ValueError):
    """An unknown key or a value of the wrong type in an agent config."""


def make_config(cls: type[C], overrides: Mapping[str, Any] | None = None, *, agent: str = "agent") -> C:
    """Builds ``cls`` (a dataclass) from its defaults updated by ``overrides``.

    Raises:
      ConfigError: a key that ``cls`` does not define (listing the valid keys), or a value that cannot
        be converted to the field's default type.
    """
    overrides = dict(overrides or {})
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ConfigError(f"unknown config key(s) {unknown} for agent {agent!r}; valid keys: {sorted(fields)}")
    values = {}
    defaults = cls()
    for name, value in overrides.items():
        default = getattr(defaults, name)
        if isinstance(default, bool) and not isinstance(value, bool):
            raise ConfigError(f"config key {name!r} of agent {agent!r} must be true or false, got {value!r}")
        if isinstance(default, int | float) and not isinstance(default, bool):
            try:
                value = type(default)(value) if not (isinstance(default, int) and isinstance(value, float)
                                                     and not value.is_integer()) else None
            except (TypeError, ValueError):
                value = None
            if value is None:
                raise ConfigError(f"config key {name!r} of agent {agent!r} must be a {type(default).__name__}, "
                                  f"got {overrides[name]!r}") from None
        if isinstance(default, tuple) and isinstance(value, list):
            value = tuple(value)
        values[name] = value
    return dataclasses.replace(defaults, **values)
