"""Which split an episode comes from, told from the key its layout is drawn with.

An arena hands a task's ``initialize`` the episode's layout key, not its id (the id's randomness is derived from it
alone: :mod:`jarena.core.episodes`). A task whose content differs between splits (assembling-kits draws unseen
shapes at evaluation, as Ravens' test mode does) tells the fixed splits' episodes apart by their keys: the
eval and val episodes are few and known when the arena is built, so their layout keys are a table, and a key found
in it is held out; any other key is a training episode's.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core import episodes


def layout_key(episode: jax.Array) -> jax.Array:
    """The key the first task of an arena's chain lays out ``episode`` (int32 ()) with: the arena's fifth piece of
    the episode (:func:`jarena.core.episodes.piece_key`), folded with the task's place in the chain (0)."""
    return jax.random.fold_in(episodes.piece_key(episode, 4), 0)


def held_out(num_eval: int, num_val: int) -> Callable[[jax.Array], jax.Array]:
    """``(key) -> bool ()``: whether a layout key (:func:`layout_key`) is one of the ``num_eval`` eval or
    ``num_val`` val episodes' (the fixed splits' ids, :func:`jarena.core.episodes.split_episodes`)."""
    ids = np.concatenate([np.asarray(episodes.split_episodes(split, num_val, num_eval), np.int64)
                          for split in ("eval", "val")]).astype(np.int32)
    with jax.ensure_compile_time_eval():
        table = np.asarray(jax.random.key_data(jax.vmap(layout_key)(jnp.asarray(ids))))

    def is_held_out(key: jax.Array) -> jax.Array:
        data = jax.random.key_data(key)
        return jnp.any(jnp.all(jnp.asarray(table) == data, axis=-1))

    return is_held_out
