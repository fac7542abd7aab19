"""The buffer's per-slot bookkeeping, packed in one int32 so that adds write, and samples read, one array.

``meta = run << 2 | done << 1 | ends``, where ``run`` is 1 + the number of items of the same episode
stored contiguously before the slot, ``done`` marks an episode's last item, and ``ends`` marks the last
item of an episode added whole from its step 0 (see :class:`jarena.data.BufferState`).
"""

import jax
import jax.numpy as jnp


def pack(run: jax.Array, done: jax.Array, ends: jax.Array) -> jax.Array:
    return (run.astype(jnp.int32) << 2) | (done.astype(jnp.int32) << 1) | ends.astype(jnp.int32)


def run(meta: jax.Array) -> jax.Array:
    return meta >> 2


def done(meta: jax.Array) -> jax.Array:
    return (meta & 2) != 0


def ends(meta: jax.Array) -> jax.Array:
    return (meta & 1) != 0
