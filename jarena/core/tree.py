"""Small pytree helpers used across the library."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp


def _is_key(x) -> bool:
    return isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def _select(pred, a, b):
    if _is_key(a):
        data = _select(pred, jax.random.key_data(a), jax.random.key_data(b))
        return jax.random.wrap_key_data(data, impl=jax.random.key_impl(a))
    pred = jnp.reshape(pred, jnp.shape(pred) + (1,) * (jnp.ndim(a) - jnp.ndim(pred)))
    return jnp.where(pred, a, b)


def tree_where(pred: jax.Array, on_true: Any, on_false: Any) -> Any:
    """Selects leaf-wise between two pytrees of one structure; ``pred`` broadcasts over trailing axes.

    ``pred`` has the leading (batch) shape of the leaves; PRNG key leaves are supported.
    """
    return jax.tree_util.tree_map(lambda a, b: _select(pred, a, b), on_true, on_false)


def as_float32(tree):
    """Every leaf of ``tree`` as a float32 array (params structs are declared with Python floats)."""
    return jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float32), tree)
