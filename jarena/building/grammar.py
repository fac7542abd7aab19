"""A small recursive-descent parser for arena strings.

Grammar (whitespace between tokens is ignored)::

    arena  := NAME [ '|' [ pair { ',' pair } ] ]
    pair   := NAME ':' value
    value  := NUMBER | STRING | NAME | call | list
    call   := NAME '(' [ arg { ',' arg } ] ')'
    arg    := NAME '=' value | value
    list   := '[' [ value { ',' value } ] ']'
    NAME   := letter or '_' then letters, digits, '_', '.', '-'
    NUMBER := optional '-', digits, optional fraction and exponent (int unless it has '.' or 'e')
    STRING := '...' or "..."

Names ``true``, ``false`` and ``none`` become ``True``, ``False`` and ``None``; other names stay
strings. ``classic|domain:cartpole,task:balance,action:[rescale(-1,1),repeat(2)]`` parses to
``ArenaString('classic', {'domain': 'cartpole', 'task': 'balance', 'action': [Call('rescale', (-1, 1)),
Call('repeat', (2,))]})``. Every error is an :class:`ArenaStringError` that points at the bad spot.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any


class ArenaStringError(ValueError):
    """A malformed or invalid arena string; the message shows where and what was expected."""


@dataclasses.dataclass(frozen=True)
class Call:
    """A call value ``name(args..., key=value...)``."""

    name: str
    args: tuple[Any, ...] = ()
    kwargs: tuple[tuple[str, Any], ...] = ()

    def __str__(self):
        parts = [format_value(a) for a in self.args] + [f"{k}={format_value(v)}" for k, v in self.kwargs]
        return f"{self.name}({','.join(parts)})"


@dataclasses.dataclass(frozen=True)
class ArenaString:
    """A parsed arena string: the builder's name and its ``key: value`` pairs, in order."""

    builder: str
    pairs: dict[str, Any]

    def __str__(self):
        if not self.pairs:
            return self.builder
        return self.builder + "|" + ",".join(f"{k}:{format_value(v)}" for k, v in self.pairs.items())


_TOKEN = re.compile(r"""
    (?P<space>\s+)
  | (?P<number>-?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_.\-]*)
  | (?P<string>'[^']*'|"[^"]*")
  | (?P<punct>[|:,()\[\]=])
""", re.VERBOSE)

_CONSTANTS = {"true": True, "false": False, "none": None}


def format_value(value: Any) -> str:
    """The inverse of parsing one value (used for canonical strings and messages)."""
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "none"}[value]
    if isinstance(value, list | tuple):
        return "[" + ",".join(format_value(v) for v in value) + "]"
    if isinstance(value, str) and not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", value):
        return repr(value)
    return str(value)


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.tokens: list[tuple[str, str, int]] = []
        pos = 0
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            if m is None:
                self.fail(pos, f"unexpected character {text[pos]!r}")
            if m.lastgroup != "space":
                self.tokens.append((m.lastgroup, m.group(), pos))
            pos = m.end()
        self.tokens.append(("end", "", len(text)))
        self.i = 0

    def fail(self, pos: int, message: str):
        raise ArenaStringError(f"{message} at position {pos} of arena string\n  {self.text}\n  {' ' * pos}^")

    def peek(self) -> tuple[str, str, int]:
        return self.tokens[self.i]

    def take(self, kind: str, value: str | None = None, expected: str | None = None) -> str:
        k, v, pos = self.peek()
        if k != kind or (value is not None and v != value):
            shown = "the end of the string" if k == "end" else repr(v)
            want = expected or (repr(value) if value else kind)
            self.fail(pos, f"expected {want}, found {shown}")
        self.i += 1
        return v

    def at(self, kind: str, value: str | None = None) -> bool:
        k, v, _ = self.peek()
        return k == kind and (value is None or v == value)

    def arena(self) -> ArenaString:
        builder = self.take("name", expected="a builder name (e.g. 'classic')")
        pairs: dict[str, Any] = {}
        if self.at("punct", "|"):
            self.i += 1
            if not self.at("end"):
                while True:
                    _, _, pos = self.peek()
                    key = self.take("name", expected="a key name")
                    self.take("punct", ":", expected=f"':' after key {key!r}")
                    if key in pairs:
                        self.fail(pos, f"key {key!r} given twice")
                    pairs[key] = self.value()
                    if not self.at("punct", ","):
                        break
                    self.i += 1
        if not self.at("end"):
            _, v, pos = self.peek()
            self.fail(pos, f"expected '|', ',' or the end of the string, found {v!r}")
        return ArenaString(builder, pairs)

    def value(self) -> Any:
        kind, text, pos = self.peek()
        if kind == "number":
            self.i += 1
            return float(text) if any(c in text for c in ".eE") else int(text)
        if kind == "string":
            self.i += 1
            return text[1:-1]
        if kind == "punct" and text == "[":
            self.i += 1
            items = []
            if not self.at("punct", "]"):
                items.append(self.value())
                while self.at("punct", ","):
                    self.i += 1
                    items.append(self.value())
            self.take("punct", "]", expected="',' or ']' to close the list")
            return items
        if kind == "name":
            self.i += 1
            if self.at("punct", "("):
                return self.call(text)
            return _CONSTANTS.get(text.lower(), text)
        shown = "the end of the string" if kind == "end" else repr(text)
        self.fail(pos, f"expected a value (number, name, call or list), found {shown}")

    def call(self, name: str) -> Call:
        self.take("punct", "(")
        args, kwargs = [], []
        if not self.at("punct", ")"):
            while True:
                _, _, pos = self.peek()
                if self.at("name") and self.tokens[self.i + 1][1] == "=":
                    key = self.take("name")
                    self.i += 1
                    if any(k == key for k, _ in kwargs):
                        self.fail(pos, f"argument {key!r} given twice to {name}(...)")
                    kwargs.append((key, self.value()))
                else:
                    if kwargs:
                        self.fail(pos, f"positional argument after keyword arguments in {name}(...)")
                    args.append(self.value())
                if not self.at("punct", ","):
                    break
                self.i += 1
        self.take("punct", ")", expected=f"',' or ')' to close {name}(...)")
        return Call(name, tuple(args), tuple(kwargs))


def parse_arena_string(text: str) -> ArenaString:
    """Parses ``builder|key:value,...`` into an :class:`ArenaString`; raises :class:`ArenaStringError`."""
    if not isinstance(text, str):
        raise ArenaStringError(f"an arena string must be a str, got {type(text).__name__}")
    if not text.strip():
        raise ArenaStringError("empty arena string; expected 'builder|key:value,...', e.g. "
                               "'classic|domain:cartpole,task:balance'")
    return _Parser(text).arena()
