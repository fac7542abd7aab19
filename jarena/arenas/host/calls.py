"""Host calls that batch: a function of numpy arrays called once per batch of arenas, from inside ``jit``.

``jax.experimental.io_callback`` keeps host calls with side effects (a simulator's step) in order and never
drops or merges them, but under ``vmap`` it calls the host once per arena. :func:`batched_host_call` wraps
it in ``jax.custom_batching.custom_vmap`` so that a ``vmap`` over B arenas makes one call with (B, ...)
arrays, as a vector env wants them; an arena outside ``vmap`` calls with a batch of one. Under a second
``vmap`` (seeds x arenas) the outer axis runs as a loop of such calls, one per row.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import io_callback

PyTree = Any


def batched_host_call(fn: Callable[..., PyTree], result: Callable[[int], PyTree]) -> Callable[..., PyTree]:
    """A JAX function of one arena's arrays that runs ``fn`` on the host, once per batch.

    Args:
      fn: ``(*arrays) -> pytree of arrays``, host numpy arrays with a leading batch axis B in and out.
      result: ``B -> pytree of jax.ShapeDtypeStruct``, the shapes ``fn`` returns for a batch of B.

    Returns:
      ``(*arrays) -> pytree``: one arena's inputs (no batch axis) to its outputs; vmap it for a batch.
    """

    def on_host(*args):  # io_callback hands over jax Arrays: numpy ones are cheaper to index and compute with
        return fn(*jax.tree_util.tree_map(np.asarray, args))

    def call(size: int, *args):
        return io_callback(on_host, result(size), *args, ordered=False)

    @jax.custom_batching.custom_vmap
    def one(*args):
        out = call(1, *(jnp.expand_dims(a, 0) for a in args))
        return jax.tree_util.tree_map(lambda x: x[0], out)

    @one.def_vmap
    def batch(axis_size, in_batched, *args):
        args = [a if batched else jnp.broadcast_to(a, (axis_size,) + jnp.shape(a))
                for a, batched in zip(args, in_batched, strict=True)]
        out = call(axis_size, *args)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return one
