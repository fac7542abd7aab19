"""MuJoCo models as jarena dynamics, stepped on MJX."""

from jarena.arenas.mjx.dynamics import MjxParams, Names, apply_params, control_spec, mjx_dynamics, physics_step

__all__ = ["MjxParams", "Names", "apply_params", "control_spec", "mjx_dynamics", "physics_step"]
