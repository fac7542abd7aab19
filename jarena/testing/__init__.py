"""Testing utilities shipped with jarena: the arena contract checker."""

from jarena.testing.contract import (
    CHECKS,
    check_arena,
    check_determinism,
    check_jit_consistency,
    check_no_retrace,
    check_rollout,
    check_vmap,
)

__all__ = ["CHECKS", "check_arena", "check_determinism", "check_jit_consistency", "check_no_retrace",
           "check_rollout", "check_vmap"]
