"""``tolerance``: dm_control's soft indicator of "x is within bounds", in JAX.

Matches ``dm_control.utils.rewards.tolerance`` value for value (tests compare the two), so the
DeepMind Control Suite's rewards can be written as in the suite.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

SIGMOIDS = ("gaussian", "hyperbolic", "long_tail", "reciprocal", "cosine", "linear", "quadratic", "tanh_squared")


def _sigmoid(x: jax.Array, value_at_1: float, sigmoid: str) -> jax.Array:
    if sigmoid in ("cosine", "linear", "quadratic"):
        if not 0 <= value_at_1 < 1:
            raise ValueError(f"value_at_margin must be in [0, 1) for the {sigmoid} sigmoid, got {value_at_1}")
    elif sigmoid in SIGMOIDS and not 0 < value_at_1 < 1:
        raise ValueError(f"value_at_margin must be in (0, 1) for the {sigmoid} sigmoid, got {value_at_1}")
    if sigmoid == "gaussian":
        return jnp.exp(-0.5 * (x * math.sqrt(-2 * math.log(value_at_1))) ** 2)
    if sigmoid == "hyperbolic":
        return 1 / jnp.cosh(x * math.acosh(1 / value_at_1))
    if sigmoid == "long_tail":
        return 1 / ((x * math.sqrt(1 / value_at_1 - 1)) ** 2 + 1)
    if sigmoid == "reciprocal":
        return 1 / (jnp.abs(x) * (1 / value_at_1 - 1) + 1)
    if sigmoid == "cosine":
        scaled = x * (math.acos(2 * value_at_1 - 1) / math.pi)
        return jnp.where(jnp.abs(scaled) < 1, (1 + jnp.cos(jnp.pi * scaled)) / 2, 0.0)
    if sigmoid == "linear":
        scaled = x * (1 - value_at_1)
        return jnp.where(jnp.abs(scaled) < 1, 1 - scaled, 0.0)
    if sigmoid == "quadratic":
        scaled = x * math.sqrt(1 - value_at_1)
        return jnp.where(jnp.abs(scaled) < 1, 1 - scaled**2, 0.0)
    if sigmoid == "tanh_squared":
        return 1 - jnp.tanh(x * math.atanh(math.sqrt(1 - value_at_1))) ** 2
    raise ValueError(f"unknown sigmoid {sigmoid!r}; choose one of {', '.join(SIGMOIDS)}")


def tolerance(x: jax.Array, bounds: tuple[float, float] = (0.0, 0.0), margin: float = 0.0,
              sigmoid: str = "gaussian", value_at_margin: float = 0.1) -> jax.Array:
    """1 where ``bounds[0] <= x <= bounds[1]``, decaying sigmoidally to ``value_at_margin`` at ``margin``
    outside (0 outside when ``margin == 0``). Same shape as ``x``, float32.

    ``bounds``, ``margin``, ``sigmoid`` and ``value_at_margin`` are static Python numbers (as in the
    suite); ``x`` may be traced.
    """
    lower, upper = bounds
    if lower > upper:
        raise ValueError(f"tolerance: lower bound {lower} > upper bound {upper}")
    if margin < 0:
        raise ValueError(f"tolerance: margin must be non-negative, got {margin}")
    x = jnp.asarray(x, jnp.float32)
    in_bounds = (lower <= x) & (x <= upper)
    if margin == 0:
        return jnp.where(in_bounds, 1.0, 0.0).astype(jnp.float32)
    distance = jnp.where(x < lower, lower - x, x - upper) / margin
    return jnp.where(in_bounds, 1.0, _sigmoid(distance, value_at_margin, sigmoid)).astype(jnp.float32)
