"""What the exported environments share: host actions cast to the arena's dtypes, and episode seeds."""

from __future__ import annotations

from typing import Any

import jax
import numpy as np

from jarena.core.arena import Arena

#: Episode keys are drawn from ``jax.random.key(s)`` with ``s`` in ``[0, SEED_RANGE)``.
SEED_RANGE = 2**31


def action_dtypes(arena: Arena) -> Any:
    """A zero action of ``arena``: the template :func:`cast_action` takes its structure and dtypes from."""
    return arena.action_spec.zeros()


def cast_action(action: Any, template: Any) -> Any:
    """``action`` (host values from a user or library: Python ints, float64 arrays) as numpy arrays of the
    arena's action dtypes, so the jitted step sees one signature and never retraces."""
    return jax.tree_util.tree_map(lambda a, t: np.asarray(a, t.dtype), action, template)
