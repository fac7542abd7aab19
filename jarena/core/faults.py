"""Fault codes: why an arena step went wrong, as the int32 bitmask ``Info.fault`` (0 = no fault).

Under ``jit`` and in batches an arena cannot raise, so :meth:`jarena.Arena.step` checks each step and
reports what it found in ``info.fault``; a faulted step ends its episode (``terminated``, reward 0,
non-finite observation entries 0: see ``Arena.step``), and auto-reset replaces it as any finished one.

Bits (:class:`Fault`):

- ``INVALID_ACTION``: the action is outside its spec in a way no dynamics can clip: a non-finite float,
  or an integer (``Discrete``, integer ``Box``) out of range. A float ``Box`` value outside its bounds is
  *not* a fault (dynamics clip it, as Gymnasium's do). The step runs ``arena.no_op()`` instead.
- ``NONFINITE_STATE``: after the step, the physics state (``Dynamics.is_finite``), the observation or
  the reward holds a NaN or an infinity.

The traceable helpers below are what ``Arena.step`` uses: a few fused reductions, no host callbacks.
"""

from __future__ import annotations

import enum
import functools
import operator
import types
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.spec import Box, Dict, Discrete, Spec, Tuple, as_spec

PyTree = Any


class Fault(enum.IntFlag):
    """The bits of ``Info.fault``; combine with ``|``, test with ``info.fault & Fault.X``."""

    INVALID_ACTION = 1
    NONFINITE_STATE = 2

    @property
    def label(self) -> str:
        """A short readable name, as reports print it (``invalid action``)."""
        return LABELS[self]

    @property
    def description(self) -> str:
        return DESCRIPTIONS[self]


#: No fault.
NONE = 0
INVALID_ACTION = Fault.INVALID_ACTION
NONFINITE_STATE = Fault.NONFINITE_STATE

#: Each fault's short name (read-only).
LABELS: Mapping[Fault, str] = types.MappingProxyType({
    Fault.INVALID_ACTION: "invalid action",
    Fault.NONFINITE_STATE: "non-finite state",
})

#: Each fault's meaning (read-only).
DESCRIPTIONS: Mapping[Fault, str] = types.MappingProxyType({
    Fault.INVALID_ACTION: "action outside its spec (non-finite float, or integer out of range); "
                          "the step ran the no-op action",
    Fault.NONFINITE_STATE: "non-finite physics state, observation or reward after the step",
})

_KNOWN = functools.reduce(operator.or_, (int(f) for f in Fault))


def _labels(mask: int) -> list[str]:
    unknown = mask & ~_KNOWN
    return ([fault.label for fault in Fault if mask & fault]
            + [f"bit {i}" for i in range(unknown.bit_length()) if unknown >> i & 1])


def describe(mask: Any) -> list[str]:
    """The labels of the faults set in ``mask`` (one int or 0-d array), lowest bit first; ``[]`` for 0.

    ``describe(3) == ["invalid action", "non-finite state"]``; bits that name no :class:`Fault` appear as
    ``"bit N"``.
    """
    return _labels(int(np.asarray(mask)))


def describe_counts(masks: Any) -> dict[str, int]:
    """How many of ``masks`` (e.g. ``EvalResult.faults``, one mask per episode) have each fault, by label,
    lowest bit first; faults that no mask has are left out (``{}`` when none faulted)."""
    counts: dict[str, int] = {}
    for mask in np.asarray(masks, np.int64).reshape(-1).tolist():
        for label in _labels(mask):
            counts[label] = counts.get(label, 0) + 1
    order = _labels(functools.reduce(operator.or_, np.asarray(masks, np.int64).reshape(-1).tolist(), 0))
    return {label: counts[label] for label in order}


def _all(parts: list[jax.Array]) -> jax.Array:
    return functools.reduce(operator.and_, parts, jnp.asarray(True))


def _floating(x) -> bool:
    return jnp.issubdtype(jnp.result_type(x), jnp.inexact)


def all_finite(tree: PyTree) -> jax.Array:
    """bool scalar: every floating leaf of ``tree`` is finite (integer, bool and key leaves are skipped)."""
    return _all([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree) if _floating(x)])


def zero_nonfinite(tree: PyTree) -> PyTree:
    """``tree`` with the NaN and infinite entries of its floating leaves replaced by 0."""
    return jax.tree_util.tree_map(lambda x: jnp.where(jnp.isfinite(x), x, jnp.zeros((), x.dtype))
                                  if _floating(x) else x, tree)


def valid_action(spec: Spec, action: PyTree) -> jax.Array:
    """bool scalar: ``action`` (already validated for shape and dtype) has no value that makes it invalid.

    Invalid are non-finite floats and integers outside their range (``Discrete(n)``: ``0 .. n - 1``,
    integer ``Box``: its bounds). Floats outside a ``Box``'s bounds are valid: dynamics clip them.
    """
    spec = as_spec(spec)
    if isinstance(spec, Dict):
        return _all([valid_action(s, action[k]) for k, s in spec.spaces.items()])
    if isinstance(spec, Tuple):
        return _all([valid_action(s, a) for s, a in zip(spec.spaces, action, strict=True)])
    x = jnp.asarray(action)
    if isinstance(spec, Discrete):
        return (x >= 0) & (x < spec.n)
    if isinstance(spec, Box):
        if _floating(x):
            return jnp.all(jnp.isfinite(x))
        if jnp.issubdtype(x.dtype, jnp.integer):
            return jnp.all((x >= jnp.asarray(spec.low, x.dtype)) & (x <= jnp.asarray(spec.high, x.dtype)))
        return jnp.asarray(True)
    raise TypeError(f"valid_action: unsupported spec {spec!r}")


def code(invalid_action: jax.Array, nonfinite_state: jax.Array) -> jax.Array:
    """The int32 fault mask from the two traced conditions."""
    return (jnp.where(invalid_action, jnp.int32(Fault.INVALID_ACTION), jnp.int32(0))
            | jnp.where(nonfinite_state, jnp.int32(Fault.NONFINITE_STATE), jnp.int32(0)))
