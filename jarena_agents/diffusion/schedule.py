"""The diffusion process of Diffusion Policy: a DDPM noise schedule for training, DDIM steps for sampling, and the
warm-up of the weights' exponential moving average. Pure functions of arrays; the caller jits.

Notation: ``T`` noise steps ``t = 0 .. T - 1``; ``alphas_cumprod[t]`` (written ``a_t``) is the fraction of the
clean sample's variance left at step ``t``: ``x_t = sqrt(a_t) x_0 + sqrt(1 - a_t) eps`` with ``eps ~ N(0, I)``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

MAX_BETA = 0.999  # the cap of squaredcos_cap_v2's per-step noise variance (the "cap")
COSINE_OFFSET = 0.008  # the cosine schedule's s (Nichol & Dhariwal 2021): keeps beta_0 away from 0


def cosine_alphas_cumprod(num_steps: int) -> np.ndarray:
    """``a_t`` of the ``squaredcos_cap_v2`` schedule (Nichol & Dhariwal 2021's cosine schedule, as Diffusion
    Policy's DDPM scheduler uses it): float32 (num_steps,).

    With ``f(s) = cos((s + 0.008) / 1.008 * pi / 2)^2``, step ``i`` adds noise of variance
    ``beta_i = min(1 - f((i + 1) / T) / f(i / T), 0.999)`` and ``a_t = prod_{i <= t} (1 - beta_i)``.
    """
    if int(num_steps) < 1:
        raise ValueError(f"the noise schedule needs at least one step, got {num_steps}")

    def f(s):
        return math.cos((s + COSINE_OFFSET) / (1 + COSINE_OFFSET) * math.pi / 2) ** 2

    betas = np.array([min(1 - f((i + 1) / num_steps) / f(i / num_steps), MAX_BETA) for i in range(num_steps)])
    return np.cumprod(1.0 - betas).astype(np.float32)


def add_noise(alphas_cumprod: jax.Array, clean: jax.Array, noise: jax.Array, t: jax.Array) -> jax.Array:
    """The forward process: ``x_t = sqrt(a_t) clean + sqrt(1 - a_t) noise``.

    Args:
      alphas_cumprod: float32 (T,).
      clean, noise: (S, ...) samples and standard normal noise.
      t: int (S,) noise steps.
    """
    a = jnp.asarray(alphas_cumprod)[t].reshape(t.shape + (1,) * (clean.ndim - t.ndim))
    return jnp.sqrt(a) * clean + jnp.sqrt(1.0 - a) * noise


def ddim_timesteps(num_train_steps: int, num_inference_steps: int) -> np.ndarray:
    """The steps a DDIM sampler visits, noisiest first: int32 (num_inference_steps,), ``t_k = k * (T // n)`` for
    ``k = n - 1 .. 0`` (so 10 of 100 steps: 90, 80, ..., 0); each step goes from ``t_k`` to ``t_k - T // n``."""
    if not 1 <= num_inference_steps <= num_train_steps:
        raise ValueError(f"inference steps must lie in [1, {num_train_steps}] (the training steps), got "
                         f"{num_inference_steps}")
    return (np.arange(num_inference_steps)[::-1] * (num_train_steps // num_inference_steps)).astype(np.int32)


def ddim_step(alphas_cumprod: jax.Array, sample: jax.Array, epsilon: jax.Array, t: jax.Array, t_prev: jax.Array,
              clip: bool = True) -> jax.Array:
    """One deterministic DDIM step (Song et al. 2021, eta = 0) from ``x_t`` to ``x_{t_prev}``.

    The clean sample is estimated as ``x_0 = (x_t - sqrt(1 - a_t) eps) / sqrt(a_t)``, clipped to [-1, 1] with
    ``clip`` (the data are normalised to that range), and the step returns
    ``sqrt(a_prev) x_0 + sqrt(1 - a_prev) eps``, where ``a_prev = 1`` for ``t_prev < 0`` (the last step lands on
    the clean estimate). ``epsilon`` is the network's noise prediction at ``(x_t, t)``.

    Args:
      alphas_cumprod: float32 (T,).
      sample, epsilon: (..., ) arrays of one shape.
      t, t_prev: int scalars.
    """
    alphas_cumprod = jnp.asarray(alphas_cumprod)
    a_t = alphas_cumprod[t]
    a_prev = jnp.where(t_prev >= 0, alphas_cumprod[jnp.maximum(t_prev, 0)], 1.0)
    clean = (sample - jnp.sqrt(1.0 - a_t) * epsilon) / jnp.sqrt(a_t)
    if clip:
        clean = jnp.clip(clean, -1.0, 1.0)
    return jnp.sqrt(a_prev) * clean + jnp.sqrt(1.0 - a_prev) * epsilon


def ddpm_step(alphas_cumprod: jax.Array, sample: jax.Array, epsilon: jax.Array, t: jax.Array, t_prev: jax.Array,
              noise: jax.Array, clip: bool = True) -> jax.Array:
    """One ancestral DDPM step (Ho et al. 2020) from ``x_t`` to ``x_{t_prev}``, the posterior's "fixed small"
    variance, as Diffusion Policy samples (diffusers' ``DDPMScheduler``, ``variance_type: fixed_small``).

    With ``a_t``, ``a_prev`` (1 for ``t_prev < 0``), ``alpha = a_t / a_prev`` and ``beta = 1 - alpha``: the clean
    estimate ``x_0 = (x_t - sqrt(1 - a_t) eps) / sqrt(a_t)`` (clipped to [-1, 1] with ``clip``), the posterior mean
    ``sqrt(a_prev) beta / (1 - a_t) x_0 + sqrt(alpha) (1 - a_prev) / (1 - a_t) x_t`` and, for ``t > 0``, its
    variance ``(1 - a_prev) / (1 - a_t) beta`` (at least 1e-20) times ``noise``'s standard normal draws.

    Args:
      alphas_cumprod: float32 (T,).
      sample, epsilon, noise: arrays of one shape.
      t, t_prev: int scalars (``t_prev = t - T / inference steps``).
    """
    alphas_cumprod = jnp.asarray(alphas_cumprod)
    a_t = alphas_cumprod[t]
    a_prev = jnp.where(t_prev >= 0, alphas_cumprod[jnp.maximum(t_prev, 0)], 1.0)
    alpha = a_t / a_prev
    beta = 1.0 - alpha
    clean = (sample - jnp.sqrt(1.0 - a_t) * epsilon) / jnp.sqrt(a_t)
    if clip:
        clean = jnp.clip(clean, -1.0, 1.0)
    mean = (jnp.sqrt(a_prev) * beta / (1.0 - a_t)) * clean + (jnp.sqrt(alpha) * (1.0 - a_prev) / (1.0 - a_t)) * sample
    variance = jnp.maximum((1.0 - a_prev) / (1.0 - a_t) * beta, 1e-20)
    return jnp.where(t > 0, mean + jnp.sqrt(variance) * noise, mean)


def ema_decay(update: jax.Array, power: float, max_decay: float) -> jax.Array:
    """The decay of the weights' moving average at optimiser update ``update`` (0 for the first), with Diffusion
    Policy's warm-up: ``1 - (1 + n)^-power`` for ``n = update - 1``, 0 while ``n <= 0`` (the average copies the
    weights), at most ``max_decay``. With power 0.75 it passes 0.999 near update 10,000 and 0.9999 near 215,000."""
    n = jnp.maximum(jnp.asarray(update, jnp.float32) - 1.0, 0.0)
    value = 1.0 - (1.0 + n) ** -power
    return jnp.where(n <= 0, 0.0, jnp.clip(value, 0.0, max_decay))


def ema_update(average, params, decay: jax.Array):
    """``decay * average + (1 - decay) * params``, leafwise."""
    return jax.tree_util.tree_map(lambda a, p: decay * a + (1.0 - decay) * p, average, params)
