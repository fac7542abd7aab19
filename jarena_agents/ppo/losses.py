"""Pure PPO kernels: generalised advantage estimation and the clipped surrogate loss.

Shapes: T time steps, B arenas. All functions are pure and jittable.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


def compute_gae(rewards: jax.Array, values: jax.Array, next_values: jax.Array, terminated: jax.Array,
                done: jax.Array, discount: float, gae_lambda: float) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimation (Schulman et al., 2016) with correct time-limit handling.

    ``delta_t = r_t + discount * (1 - terminated_t) * next_values_t - values_t`` and
    ``A_t = delta_t + discount * gae_lambda * (1 - done_t) * A_{t+1}``. ``next_values_t`` is the value
    of the observation reached by step t *in the same episode* (jarena's ``info.final.observation``),
    so a truncated episode bootstraps from its last state instead of being cut to zero, and no
    advantage leaks across an episode boundary (``done = terminated | truncated``).

    Args:
      rewards: float (T, B), ``r_t``.
      values: float (T, B), the values of the observations acted on.
      next_values: float (T, B), ``next_values_t`` as above.
      terminated: bool (T, B), ``terminated_t``.
      done: bool (T, B), ``terminated | truncated``.

    Returns:
      ``(advantages, returns)``, float (T, B), with ``returns = advantages + values``; no gradient.
    """
    not_terminated = 1.0 - terminated.astype(rewards.dtype)
    not_done = 1.0 - done.astype(rewards.dtype)
    deltas = rewards + discount * not_terminated * next_values - values

    def backward(advantage, xs):
        delta, carry_on = xs
        advantage = delta + discount * gae_lambda * carry_on * advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(values[0]), (deltas, not_done), reverse=True)
    return jax.lax.stop_gradient(advantages), jax.lax.stop_gradient(advantages + values)


@struct.dataclass
class PPOLossTerms:
    """Scalars reported by :func:`ppo_loss`."""

    total: jax.Array
    policy: jax.Array
    value: jax.Array
    entropy: jax.Array
    approx_kl: jax.Array
    clip_fraction: jax.Array


def standardized(advantages: jax.Array) -> jax.Array:
    """Advantages of a minibatch (any shape) shifted to mean 0 and scaled to standard deviation 1."""
    return (advantages - advantages.mean()) / (advantages.std() + 1e-8)


def ppo_loss(log_prob: jax.Array, old_log_prob: jax.Array, advantages: jax.Array, values: jax.Array,
             old_values: jax.Array, returns: jax.Array, entropy: jax.Array, *, clip_epsilon: float = 0.2,
             value_coef: float = 0.5, entropy_coef: float = 0.0, value_clip: float | None = None,
             normalize_advantages: bool = True) -> PPOLossTerms:
    """The PPO clipped objective (Schulman et al., 2017), averaged over a minibatch of any shape.

    ``policy = -mean(min(r A, clip(r, 1 - eps, 1 + eps) A))`` with ``r = exp(log_prob - old_log_prob)``;
    ``value = mean((values - returns)^2) / 2`` (or the clipped variant when ``value_clip`` is set);
    ``total = policy + value_coef * value - entropy_coef * mean(entropy)``.
    """
    if normalize_advantages:
        advantages = standardized(advantages)
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    unclipped = ratio * advantages
    clipped = jnp.clip(ratio, 1.0 - clip_epsilon, 1.0 + clip_epsilon) * advantages
    policy = -jnp.mean(jnp.minimum(unclipped, clipped))
    value_error = (values - returns) ** 2
    if value_clip is not None:
        clipped_values = old_values + jnp.clip(values - old_values, -value_clip, value_clip)
        value_error = jnp.maximum(value_error, (clipped_values - returns) ** 2)
    value = 0.5 * jnp.mean(value_error)
    mean_entropy = jnp.mean(entropy)
    total = policy + value_coef * value - entropy_coef * mean_entropy
    return PPOLossTerms(total=total, policy=policy, value=value, entropy=mean_entropy,
                        approx_kl=jnp.mean((ratio - 1.0) - log_ratio),
                        clip_fraction=jnp.mean((jnp.abs(ratio - 1.0) > clip_epsilon).astype(jnp.float32)))
