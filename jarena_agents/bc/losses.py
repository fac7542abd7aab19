"""Behaviour cloning losses: pure functions of predictions and demonstrated actions.

Each returns a float32 scalar: the per-action loss (summed over action dimensions) averaged over every
leading axis (batch, and the chunk of predicted steps).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def mse(prediction: jax.Array, target: jax.Array) -> jax.Array:
    """Squared error of the action vector: ``mean(sum_d (prediction - target)^2)``; both (..., d)."""
    return jnp.mean(jnp.sum(jnp.square(prediction - target), axis=-1))


def gaussian_nll(mean: jax.Array, log_std: jax.Array, target: jax.Array, beta: float = 0.0) -> jax.Array:
    """Negative log-likelihood of ``target`` under a diagonal Gaussian; all (..., d).

    ``mean(sum_d w [(target - mean)^2 / (2 std^2) + log std + log(2 pi) / 2])`` with per-dimension weights
    ``w = stop_gradient(std^(2 beta))`` (beta-NLL, Seitzer et al. 2022). ``beta = 0`` is the plain NLL, whose
    gradient on the mean scales as 1 / std^2: a network may then fit the easy samples with a tiny std and
    give up on the rest with a large one. ``beta = 1`` gives the mean the gradient of the squared error.
    """
    z = (target - mean) * jnp.exp(-log_std)
    weight = jax.lax.stop_gradient(jnp.exp(2.0 * beta * log_std))
    return jnp.mean(jnp.sum(weight * (0.5 * jnp.square(z) + log_std + 0.5 * jnp.log(2.0 * jnp.pi)), axis=-1))


def cross_entropy(logits: jax.Array, target: jax.Array) -> jax.Array:
    """``mean(-log softmax(logits)[target])``; logits (..., n), target int (...)."""
    logp = jax.nn.log_softmax(logits, axis=-1)
    return -jnp.mean(jnp.take_along_axis(logp, target[..., None].astype(jnp.int32), axis=-1)[..., 0])


def mixture_nll(logits: jax.Array, means: jax.Array, log_stds: jax.Array, target: jax.Array) -> jax.Array:
    """Negative log-likelihood of ``target`` (..., d) under a mixture of M diagonal Gaussians (a mixture
    density network's output, Bishop 1994; robomimic's GMM policy): mixture ``logits`` (..., M), component
    ``means`` and ``log_stds`` (..., M, d).

    ``mean(-log sum_m softmax(logits)_m N(target; means_m, exp(log_stds_m)))``, by log-sum-exp. Unlike one
    Gaussian or the squared error, it can put its mass on several distinct actions (pull this corner or that
    one) instead of on their average.
    """
    z = (target[..., None, :] - means) * jnp.exp(-log_stds)
    component = -jnp.sum(0.5 * jnp.square(z) + log_stds + 0.5 * jnp.log(2.0 * jnp.pi), axis=-1)  # (..., M)
    return -jnp.mean(jax.nn.logsumexp(jax.nn.log_softmax(logits, axis=-1) + component, axis=-1))
