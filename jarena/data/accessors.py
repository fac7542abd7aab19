"""How the buffer reads an item's episode id, step and end-of-episode flag (to find episode boundaries)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax

Array = jax.Array
PyTree = Any


class BufferError(ValueError):
    """Bad buffer arguments, or a batch whose structure, shapes or dtypes do not fit the buffer."""


def field(name: str) -> Callable[[PyTree], Array]:
    """An accessor reading ``name`` from an item or batch (attribute, or key of a mapping)."""

    def get(x):
        try:
            return x[name] if isinstance(x, Mapping) else getattr(x, name)
        except (KeyError, AttributeError):
            raise BufferError(f"the buffer reads {name!r} from each item to find episode boundaries, but "
                              f"{type(x).__name__} has no {name!r}; store items with 'episode', 'step', "
                              f"'terminated' and 'truncated' (e.g. jarena.data.Experience), or pass "
                              f"episode_of=, step_of=, done_of= to make_buffer") from None

    return get


def _terminated_or_truncated(x) -> Array:
    return field("terminated")(x) | field("truncated")(x)


@dataclasses.dataclass(frozen=True)
class Accessors:
    """Functions of an item, or of a batch of items (any leading axes), returning arrays of those axes.

    Attributes:
      episode_of: int episode id.
      step_of: int index of the item within its episode.
      done_of: bool, the episode ended with this item.
    """

    episode_of: Callable[[PyTree], Array] = field("episode")
    step_of: Callable[[PyTree], Array] = field("step")
    done_of: Callable[[PyTree], Array] = _terminated_or_truncated


DEFAULT = Accessors()
