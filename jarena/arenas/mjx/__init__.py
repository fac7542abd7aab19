"""MuJoCo models as jarena dynamics, stepped on MJX.

The names below load MuJoCo on first use, so that the pure-JAX submodules (``raycast``) import without it.
"""

import importlib
from typing import Any

__all__ = ["MjxParams", "Names", "apply_params", "control_spec", "mjx_dynamics", "physics_step"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module("jarena.arenas.mjx.dynamics"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
