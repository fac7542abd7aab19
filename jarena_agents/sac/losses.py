"""Pure SAC kernels (Haarnoja et al., 2018, "SAC v2"): the tanh-squashed Gaussian, the twin-critic,
actor and temperature losses, and the Polyak update of target networks.

Shapes: N samples (a minibatch), D action dimensions. Every function is pure and jittable; the losses
take network outputs as arrays, so they are independent of the networks that produce them.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

PyTree = Any

LOG_2 = 0.6931471805599453


def tanh_log_det(pre_tanh: jax.Array) -> jax.Array:
    """``sum_d log(1 - tanh(u_d)^2)``, float (N,) from (N, D), computed stably as ``2 (log 2 - u - softplus(-2u))``."""
    return jnp.sum(2.0 * (LOG_2 - pre_tanh - jax.nn.softplus(-2.0 * pre_tanh)), axis=-1)


def squashed_gaussian_log_prob(pre_tanh: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Log density (N,) of ``a = tanh(u)``, ``u ~ Normal(mean, exp(log_std))`` (all (N, D)), at ``u = pre_tanh``.

    By the change of variables, ``log pi(a) = log Normal(u; mean, std) - sum_d log(1 - tanh(u_d)^2)``.
    """
    z = (pre_tanh - mean) * jnp.exp(-log_std)
    gaussian = jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2.0 * jnp.pi), axis=-1)
    return gaussian - tanh_log_det(pre_tanh)


def sample_squashed_gaussian(key: jax.Array, mean: jax.Array, log_std: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A reparameterised sample ``a = tanh(mean + std * eps)`` in (-1, 1), (N, D), and its log density (N,).

    Gradients flow to ``mean`` and ``log_std`` through the sample (the reparameterisation trick).
    """
    pre_tanh = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)
    return jnp.tanh(pre_tanh), squashed_gaussian_log_prob(pre_tanh, mean, log_std)


@struct.dataclass
class CriticTerms:
    """Scalars reported by :func:`critic_loss`."""

    loss: jax.Array
    q1: jax.Array  # mean Q1 of the batch
    q2: jax.Array
    target: jax.Array  # mean TD target


def critic_loss(q1: jax.Array, q2: jax.Array, next_target_q1: jax.Array, next_target_q2: jax.Array,
                next_log_prob: jax.Array, reward: jax.Array, terminated: jax.Array, alpha: jax.Array,
                discount: float) -> tuple[jax.Array, CriticTerms]:
    """The soft Bellman residual of twin critics, averaged over the batch (all inputs (N,)).

    ``y = reward + discount * (1 - terminated) * (min(Q1', Q2') - alpha * log pi(a'|s'))`` with ``Q'`` the
    *target* critics at the next observation and ``a' ~ pi(.|s')`` from the current actor; ``y`` carries
    no gradient. ``loss = mean((Q1 - y)^2) / 2 + mean((Q2 - y)^2) / 2``. Only ``terminated`` stops
    bootstrapping: a truncated (time-limited) step keeps the value of the state it reached.
    """
    soft_value = jnp.minimum(next_target_q1, next_target_q2) - alpha * next_log_prob
    target = reward + discount * (1.0 - terminated.astype(reward.dtype)) * soft_value
    target = jax.lax.stop_gradient(target)
    loss = 0.5 * jnp.mean((q1 - target) ** 2) + 0.5 * jnp.mean((q2 - target) ** 2)
    return loss, CriticTerms(loss=loss, q1=jnp.mean(q1), q2=jnp.mean(q2), target=jnp.mean(target))


def actor_loss(log_prob: jax.Array, q1: jax.Array, q2: jax.Array, alpha: jax.Array) -> jax.Array:
    """``mean(alpha * log pi(a|s) - min(Q1(s, a), Q2(s, a)))`` for reparameterised ``a ~ pi(.|s)`` (inputs (N,)).

    ``alpha`` carries no gradient (the temperature has its own loss).
    """
    alpha = jax.lax.stop_gradient(alpha)
    return jnp.mean(alpha * log_prob - jnp.minimum(q1, q2))


def temperature_loss(log_alpha: jax.Array, log_prob: jax.Array, target_entropy: float) -> jax.Array:
    """``-mean(log_alpha * (log pi(a|s) + target_entropy))``, with ``log_prob`` (N,) carrying no gradient.

    Its gradient in ``log_alpha`` is ``entropy - target_entropy`` (entropy estimated as ``-mean(log pi)``):
    descending it raises ``alpha`` while the policy's entropy is below the target and lowers it above.
    Parameterised by ``log alpha`` (as Stable-Baselines3) so ``alpha = exp(log_alpha)`` stays positive.
    """
    return -jnp.mean(log_alpha * jax.lax.stop_gradient(log_prob + target_entropy))


def polyak_update(target: PyTree, online: PyTree, tau: float) -> PyTree:
    """``tau * online + (1 - tau) * target``, leaf by leaf (Polyak averaging of target networks)."""
    return jax.tree_util.tree_map(lambda t, o: tau * o + (1.0 - tau) * t, target, online)
