"""``BufferState``: the contents of a replay buffer (:mod:`jarena.data.buffer` writes them, and
:mod:`jarena.data.sampling` reads them)."""

from __future__ import annotations

from typing import Any

import jax
from flax import struct

from jarena.data import marks

Array = jax.Array
PyTree = Any


@struct.dataclass
class BufferState:
    """The buffer's contents (C = capacity per arena, B = number of arenas).

    Attributes:
      experience: the items, leaves of shape (C, B, *item_shape).
      meta: int32 (C, B), per slot ``run << 2 | done << 1 | ends`` (:mod:`jarena.data.marks`); read it through
        the properties below.
      last_episode: int32 (B,), episode id of each arena's newest item. It and the next two are kept apart
        so that ``add`` never reads the big arrays it writes, which would make XLA copy them.
      last_step: int32 (B,), step of each arena's newest item.
      last_run: int32 (B,), run of each arena's newest item.
      position: int32 scalar, the next slot to write (the same for every arena).
      count: int32 scalar, items stored per arena (at most C).
    """

    experience: PyTree
    meta: Array
    last_episode: Array
    last_step: Array
    last_run: Array
    position: Array
    count: Array

    @property
    def run(self) -> Array:
        """int32 (C, B); 1 + the number of items of the same episode stored contiguously before each slot
        (1 where an episode's stored stretch starts; it counts items since overwritten, too)."""
        return marks.run(self.meta)

    @property
    def done(self) -> Array:
        """bool (C, B); the episode ended with this item."""
        return marks.done(self.meta)

    @property
    def ends(self) -> Array:
        """bool (C, B); this item ends an episode added from its step 0 on, contiguously (the episode is
        stored whole while its first item is, i.e. while ``run`` <= the slot's age + 1)."""
        return marks.ends(self.meta)

    @property
    def size(self) -> Array:
        """Items stored, over all arenas."""
        return self.count * self.meta.shape[1]
