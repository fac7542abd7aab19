"""Agent configs: frozen dataclasses built from dicts, with clear errors for unknown or bad keys.

A field states its valid range declaratively, through its default::

    @dataclasses.dataclass(frozen=True)
    class MyConfig:
        num_arenas: int = at_least(1, default=4)
        learning_rate: float = positive(3e-4)
        discount: float = in_unit_interval(0.99, open_low=True)  # (0, 1]
        max_grad_norm: float | None = positive(0.5)  # null skips the check
        k_p: float = unbounded(9.0)  # a feedback gain: either sign is meaningful

and :func:`make_config` raises a ``ConfigError`` naming the key, the value and the range. NaN is in no
range, not even ``unbounded``'s.
"""

from __future__ import annotations

import dataclasses
import types
import typing
import warnings
from collections.abc import Mapping
from typing import Any, TypeVar

C = TypeVar("C")


class ConfigError(ValueError):
    """An unknown key, or a value of the wrong type or out of range, in an agent config."""


@dataclasses.dataclass(frozen=True)
class Range:
    """The valid values of a numeric config field: ``low`` to ``high`` (``None``: unbounded), each end
    open (excluded) or closed (included). NaN is in no range."""

    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False

    def __contains__(self, value) -> bool:
        if value != value:  # NaN
            return False
        above = self.low is None or (value > self.low if self.open_low else value >= self.low)
        below = self.high is None or (value < self.high if self.open_high else value <= self.high)
        return bool(above and below)

    def __str__(self) -> str:
        if self.low is None and self.high is None:
            return "a number (not NaN)"
        if self.high is None:
            return f"{'>' if self.open_low else '>='} {self.low:g}"
        if self.low is None:
            return f"{'<' if self.open_high else '<='} {self.high:g}"
        return f"in {'(' if self.open_low else '['}{self.low:g}, {self.high:g}{')' if self.open_high else ']'}"


def ranged(default, valid: Range) -> Any:
    """A dataclass field with ``default`` whose values must lie in ``valid`` (``None`` is not checked)."""
    if default is not None and default not in valid:
        raise ValueError(f"default {default!r} is not {valid}")
    return dataclasses.field(default=default, metadata={"range": valid})


def unbounded(default) -> Any:
    """A numeric field that takes any number but NaN (e.g. feedback gains, whose sign is meaningful)."""
    return ranged(default, Range())


def positive(default) -> Any:
    """A field whose values must be > 0 (rates, scales, temperatures)."""
    return ranged(default, Range(0, open_low=True))


def non_negative(default) -> Any:
    """A field whose values must be >= 0 (loss coefficients, costs, noise scales)."""
    return ranged(default, Range(0))


def at_least(low, *, default) -> Any:
    """A field whose values must be >= ``low`` (counts: ``at_least(1, default=4)``)."""
    return ranged(default, Range(low))


def in_unit_interval(default, *, open_low: bool = False, open_high: bool = False) -> Any:
    """A field whose values must lie in [0, 1], each end optionally open (discounts: ``open_low=True``)."""
    return ranged(default, Range(0, 1, open_low, open_high))


class ArenaSchedule:
    """The update schedule of a config with ``num_arenas``, ``rollout_length`` and ``total_steps`` fields:
    one update collects ``rollout_length`` steps of every arena."""

    @property
    def steps_per_update(self) -> int:
        return self.num_arenas * self.rollout_length

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.steps_per_update)


class DatasetSchedule:
    """The update schedule of a config trained from a dataset (``total_steps`` field): it takes no environment
    steps, so one "step" is one gradient update."""

    @property
    def steps_per_update(self) -> int:
        return 1

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps)

    @property
    def step_unit(self) -> str:
        """What ``total_steps`` counts (the ``jarena train`` command prints it)."""
        return "gradient updates"


def make_config(cls: type[C], overrides: Mapping[str, Any] | None = None, *, agent: str = "agent") -> C:
    """Builds ``cls`` (a dataclass) from its defaults updated by ``overrides``.

    Raises:
      ConfigError: a key that ``cls`` does not define (listing the valid keys), a value that cannot
        be converted to the field's annotated type (``null`` only where the annotation allows ``None``),
        or a value outside its field's declared :class:`Range`.
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
    config = dataclasses.replace(defaults, **values)
    _check_ranges(config, agent)
    return config


def _check_ranges(config: Any, agent: str) -> None:
    """Raises ``ConfigError`` for the first field whose value lies outside its declared range."""
    for field in dataclasses.fields(config):
        valid, value = field.metadata.get("range"), getattr(config, field.name)
        if valid is not None and value is not None and value not in valid:
            raise ConfigError(f"config key {field.name!r} of agent {agent!r} must be {valid}, got {value!r}")


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
            except (TypeError, ValueError, OverflowError):
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


def rounded_buffer(cfg: C, agent: str) -> C:
    """``cfg`` with ``buffer_size`` rounded down to a multiple of ``num_arenas`` (each arena keeps
    ``buffer_size // num_arenas`` items), warning when that changes it: raising ``num_arenas`` should not make a
    config with a round ``buffer_size`` fail."""
    size = cfg.buffer_size - cfg.buffer_size % cfg.num_arenas
    if size == cfg.buffer_size:
        return cfg
    warnings.warn(f"{agent}: buffer_size={cfg.buffer_size} is not a multiple of num_arenas={cfg.num_arenas}; "
                  f"using buffer_size={size} ({size // cfg.num_arenas} steps per arena)", stacklevel=3)
    return dataclasses.replace(cfg, buffer_size=size)
