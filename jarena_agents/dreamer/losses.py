"""DreamerV3's actor-critic objectives over imagined trajectories (Hafner et al. 2023, arXiv 2301.04104, sec. 3).

Imagined trajectories are time-major here: ``rewards``, ``continues`` and ``values`` have shape (H + 1, N) for a
start state and H imagined steps (index 0 is the start, whose reward is not used).

- :func:`lambda_returns`: ``R_t = r_{t+1} + gamma c_{t+1} ((1 - lambda) v_{t+1} + lambda R_{t+1})``, bootstrapped
  with ``R_H = v_H``; shape (H, N).
- :class:`ReturnScale`: the return normaliser: an exponential moving average (decay 0.99) of the 5th and 95th
  percentiles of the returns; advantages are divided by ``max(1, P95 - P5)``, so that large returns are scaled
  down and small ones are not scaled up.
- :func:`actor_loss`: REINFORCE with the normalised advantage ``sg((R_t - v_t) / max(1, S))`` and an entropy
  bonus ``eta H[pi]`` (eta = 3e-4), weighted by the probability that the trajectory is still alive;
  :func:`backprop_actor_loss` maximises the advantage itself, differentiated through the imagination.
- :func:`critic_loss`: two-hot cross-entropy of the critic against ``sg(R_t)``, plus the same against the slow
  (EMA) critic's prediction, which keeps the critic from drifting (weight 1 as DreamerV3).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from jarena_agents.world_model import distributions as dist


def lambda_returns(rewards: jax.Array, continues: jax.Array, values: jax.Array, discount: float,
                   lam: float, unroll: int = 1) -> jax.Array:
    """TD(lambda) returns (H, N) of an imagined trajectory; inputs (H + 1, N), ``continues`` in [0, 1];
    ``unroll``: steps per loop iteration (speed only)."""
    def step(following, inputs):
        reward, cont, value = inputs
        ret = reward + discount * cont * ((1 - lam) * value + lam * following)
        return ret, ret

    _, returns = jax.lax.scan(step, values[-1], (rewards[1:], continues[1:], values[1:]), reverse=True,
                              unroll=unroll)
    return returns


def trajectory_weights(continues: jax.Array, discount: float) -> jax.Array:
    """How much step t of each trajectory counts, (H, N): ``discount^t prod_{1 <= k <= t} c_k`` (the start counts
    1; a step after a predicted episode end counts less), from ``continues`` (H + 1, N)."""
    alive = jnp.cumprod(discount * continues[:-1].at[0].set(1.0), axis=0) / discount
    return jax.lax.stop_gradient(alive)


@struct.dataclass
class ReturnScale:
    """EMA of the returns' 5th and 95th percentiles (float32 scalars); starts at zero."""

    low: jax.Array
    high: jax.Array

    @classmethod
    def create(cls) -> ReturnScale:
        return cls(jnp.zeros((), jnp.float32), jnp.zeros((), jnp.float32))

    def update(self, returns: jax.Array, decay: float = 0.99) -> ReturnScale:
        low = jnp.percentile(returns, 5.0)
        high = jnp.percentile(returns, 95.0)
        return ReturnScale(decay * self.low + (1 - decay) * low, decay * self.high + (1 - decay) * high)

    @property
    def scale(self) -> jax.Array:
        """``max(1, P95 - P5)``: what advantages are divided by."""
        return jnp.maximum(1.0, self.high - self.low)


def actor_loss(log_probs: jax.Array, entropies: jax.Array, returns: jax.Array, values: jax.Array,
               weights: jax.Array, scale: jax.Array, entropy_coef: float = 3e-4) -> jax.Array:
    """Scalar REINFORCE loss over (H, N): ``-mean(w (sg(A) log pi + eta H))``, ``A = (R - v) / scale``."""
    advantage = jax.lax.stop_gradient((returns - values) / scale)
    return -jnp.mean(weights * (advantage * log_probs + entropy_coef * entropies))


def backprop_actor_loss(entropies: jax.Array, returns: jax.Array, values: jax.Array, weights: jax.Array,
                        scale: jax.Array, entropy_coef: float = 3e-4) -> jax.Array:
    """Scalar loss over (H, N) that maximises the normalised advantage itself, ``-mean(w (A + eta H))`` with
    ``A = (R - v) / sg(scale)``: ``returns`` and ``values`` carry the gradients of an imagination the actor's
    actions drove (DreamerV3 2023's ``actor_grad_cont: backprop``); ``weights`` are constants."""
    advantage = (returns - values) / jax.lax.stop_gradient(scale)
    return -jnp.mean(jax.lax.stop_gradient(weights) * (advantage + entropy_coef * entropies))


def critic_loss(logits: jax.Array, returns: jax.Array, slow_values: jax.Array, weights: jax.Array,
                centres: jax.Array, slow_weight: float = 1.0) -> jax.Array:
    """Scalar two-hot loss of critic ``logits`` (H, N, K) against ``sg(returns)`` and the slow critic's values."""
    target = dist.two_hot_loss(logits, jax.lax.stop_gradient(returns), centres)
    slow = dist.two_hot_loss(logits, jax.lax.stop_gradient(slow_values), centres)
    return jnp.mean(weights * (target + slow_weight * slow))


def ema(slow, fast, rate: float = 0.02):
    """The slow critic's update: ``slow + rate (fast - slow)`` leafwise (DreamerV3: rate 0.02 every step)."""
    return jax.tree_util.tree_map(lambda s, f: s + rate * (f - s), slow, fast)
