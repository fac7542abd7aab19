"""The distributions of a DreamerV3 world model (Hafner et al. 2023, arXiv 2301.04104), as pure functions.

- ``symlog`` / ``symexp``: the squashing that lets one set of hyperparameters fit rewards and observations of
  any scale: ``symlog(x) = sign(x) log(1 + |x|)``.
- Two-hot regression (rewards, values): a softmax over fixed ``bins`` in symlog space; the target ``y`` is
  ``symlog(y)`` spread over its two neighbouring bins in proportion to the distance; the prediction is
  ``symexp(E[bins])``. DreamerV3's bins: 255 equally spaced in [-20, 20].
- Categorical latents: ``(..., stoch, classes)`` logits, mixed with 1% uniform ("unimix") so that no class
  has zero probability, sampled as one-hot vectors with straight-through gradients; KL divergences between
  them summed over the ``stoch`` variables.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

UNIMIX = 0.01  # DreamerV3: 1% uniform mixed into every categorical


def symlog(x: jax.Array) -> jax.Array:
    """``sign(x) log(1 + |x|)``, elementwise."""
    return jnp.sign(x) * jnp.log1p(jnp.abs(x))


def symexp(x: jax.Array) -> jax.Array:
    """The inverse of :func:`symlog`: ``sign(x) (exp(|x|) - 1)``."""
    return jnp.sign(x) * jnp.expm1(jnp.abs(x))


def bins(num: int = 255, low: float = -20.0, high: float = 20.0) -> jax.Array:
    """``num`` equally spaced bin centres in symlog space (DreamerV3's: 255 in [-20, 20]), float32 (num,)."""
    return jnp.asarray(np.linspace(low, high, num), jnp.float32)  # float64 spacing: the middle bin is exactly 0


def two_hot(y: jax.Array, centres: jax.Array) -> jax.Array:
    """``symlog(y)`` as weights on its two nearest ``centres``: float32 (*y.shape, K), each row sums to 1.

    A value between centres ``b_k <= s < b_{k+1}`` puts ``(b_{k+1} - s) / (b_{k+1} - b_k)`` on ``k`` and the
    rest on ``k + 1``; values beyond the outer centres put everything on the outer one.
    """
    s = jnp.clip(symlog(y), centres[0], centres[-1])
    above = jnp.clip(jnp.searchsorted(centres, s, side="right"), 1, centres.shape[0] - 1)
    below = above - 1
    width = centres[above] - centres[below]
    weight_above = (s - centres[below]) / width
    k = centres.shape[0]
    return (jax.nn.one_hot(below, k) * (1 - weight_above)[..., None]
            + jax.nn.one_hot(above, k) * weight_above[..., None])


def two_hot_mean(logits: jax.Array, centres: jax.Array) -> jax.Array:
    """The prediction of two-hot ``logits`` (*, K): ``symexp(sum(softmax(logits) * centres))``, shape (*)."""
    return symexp(jnp.sum(jax.nn.softmax(logits, axis=-1) * centres, axis=-1))


def two_hot_loss(logits: jax.Array, y: jax.Array, centres: jax.Array) -> jax.Array:
    """Cross-entropy of two-hot ``logits`` (*, K) against targets ``y`` (*): shape (*), in nats."""
    return -jnp.sum(two_hot(y, centres) * jax.nn.log_softmax(logits, axis=-1), axis=-1)


def categorical_probs(logits: jax.Array, unimix: float = UNIMIX) -> jax.Array:
    """Probabilities of ``logits`` (..., classes) mixed with ``unimix`` of the uniform distribution."""
    probs = jax.nn.softmax(logits, axis=-1)
    return (1 - unimix) * probs + unimix / logits.shape[-1]


def sample_one_hot(key: jax.Array, probs: jax.Array) -> jax.Array:
    """A one-hot sample (..., classes) of ``probs`` with straight-through gradients (those of ``probs``)."""
    index = jax.random.categorical(key, jnp.log(probs), axis=-1)
    sample = jax.nn.one_hot(index, probs.shape[-1], dtype=probs.dtype)
    return sample + probs - jax.lax.stop_gradient(probs)


def mode_one_hot(probs: jax.Array) -> jax.Array:
    """The most likely class as a one-hot vector (..., classes), straight-through as :func:`sample_one_hot`."""
    sample = jax.nn.one_hot(jnp.argmax(probs, axis=-1), probs.shape[-1], dtype=probs.dtype)
    return sample + probs - jax.lax.stop_gradient(probs)


def categorical_kl(p: jax.Array, q: jax.Array) -> jax.Array:
    """``KL(p || q)`` of independent categoricals (..., stoch, classes), summed over ``stoch``: shape (...)."""
    return jnp.sum(p * (jnp.log(p) - jnp.log(q)), axis=(-2, -1))


def categorical_entropy(p: jax.Array) -> jax.Array:
    """Entropy of independent categoricals (..., stoch, classes), summed over ``stoch``: shape (...)."""
    return -jnp.sum(p * jnp.log(p), axis=(-2, -1))


def bernoulli_loss(logits: jax.Array, target: jax.Array) -> jax.Array:
    """Negative log-likelihood of ``target`` in {0, 1} under Bernoulli ``logits``, elementwise."""
    return -(target * jax.nn.log_sigmoid(logits) + (1 - target) * jax.nn.log_sigmoid(-logits))
