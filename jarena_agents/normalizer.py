"""A functional running normaliser for observations (Welford / Chan et al. parallel update)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class RunningStatistics:
    """count: float32 scalar; mean, var: float32 (D,) over all samples seen."""

    count: jax.Array
    mean: jax.Array
    var: jax.Array


def init(dim: int) -> RunningStatistics:
    return RunningStatistics(count=jnp.zeros((), jnp.float32), mean=jnp.zeros((dim,), jnp.float32),
                             var=jnp.ones((dim,), jnp.float32))


def update(stats: RunningStatistics, batch: jax.Array) -> RunningStatistics:
    """Merges a batch (N, D) into the statistics (exact, order-independent up to rounding)."""
    batch = batch.reshape(-1, stats.mean.shape[0]).astype(jnp.float32)
    n = jnp.asarray(batch.shape[0], jnp.float32)
    batch_mean = batch.mean(0)
    batch_var = batch.var(0)
    total = stats.count + n
    delta = batch_mean - stats.mean
    mean = stats.mean + delta * n / total
    m2 = stats.var * stats.count + batch_var * n + delta**2 * stats.count * n / total
    return RunningStatistics(count=total, mean=mean, var=m2 / total)


def normalize(stats: RunningStatistics, x: jax.Array, clip: float = 10.0) -> jax.Array:
    """``(x - mean) / std`` clipped to ``[-clip, clip]``; identity before any update."""
    std = jnp.sqrt(jnp.maximum(stats.var, 1e-8))
    return jnp.clip((x - stats.mean) / std, -clip, clip)
