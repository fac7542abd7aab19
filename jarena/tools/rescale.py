"""``rescale`` and ``clip``: map or bound the agent's action into the control range."""

from __future__ import annotations

import jax.numpy as jnp

from jarena.core.spec import Box, Spec
from jarena.core.tool import ActionTool


def _require_bounded_box(spec: Spec, tool: str) -> Box:
    if not isinstance(spec, Box) or not spec.bounded or spec.dtype.kind != "f":
        raise TypeError(f"{tool} needs a bounded float Box to drive, got {spec!r}")
    return spec


def rescale(low: float = -1.0, high: float = 1.0) -> ActionTool:
    """Accepts actions in ``[low, high]`` and maps them affinely onto the inner Box's bounds."""
    if not low < high:
        raise ValueError(f"rescale needs low < high, got low={low}, high={high}")

    def spec(inner):
        inner = _require_bounded_box(inner, "rescale")
        return Box(low, high, inner.shape, inner.dtype)

    def to_inner(action, inner):
        lo, hi = jnp.asarray(inner.low, inner.dtype), jnp.asarray(inner.high, inner.dtype)
        return lo + (action - low) * (hi - lo) / (high - low)

    def step(state, action, carry, inner_step, params, inner):
        carry, outcome = inner_step(carry, to_inner(action, inner))
        return carry, outcome, state

    def no_op(inner_no_op, inner):
        lo, hi = jnp.asarray(inner.low, inner.dtype), jnp.asarray(inner.high, inner.dtype)
        return (low + (inner_no_op - lo) * (high - low) / (hi - lo)).astype(inner.dtype)

    return ActionTool(step=step, spec=spec, no_op=no_op, name=f"rescale({low}, {high})")


def clip() -> ActionTool:
    """Clips the action into the inner Box's bounds before applying it (the spec is unchanged)."""

    def step(state, action, carry, inner_step, params, inner):
        inner = _require_bounded_box(inner, "clip")
        action = jnp.clip(action, jnp.asarray(inner.low, inner.dtype), jnp.asarray(inner.high, inner.dtype))
        carry, outcome = inner_step(carry, action)
        return carry, outcome, state

    return ActionTool(step=step, name="clip")
