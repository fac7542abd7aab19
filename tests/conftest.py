"""Test configuration: JAX's persistent compilation cache keeps the suite fast on small CPU machines."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; also keeps dm_control from probing X11

from jarena.platform import avoid_cpu_eigen_deadlock, enable_compilation_cache

avoid_cpu_eigen_deadlock(force=True)  # before JAX starts its CPU backend
# LLVM at -O1 instead of XLA:CPU's default: the suite is mostly compilation (a cold cache in CI), and at -O1 it
# compiles enough faster to win even on the tests that compute most (tests/core, tasks and building: 101 -> 87-92 s
# of CPU; PlaNet's learning test and the cloth physics tests: 189 -> 165 s). The programs are the same; only the
# machine code's speed differs. A level the user set is kept.
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=1").strip()
os.environ.setdefault("JARENA_COMPILATION_CACHE", os.path.expanduser("~/.cache/jarena/jax"))  # the suite's own
enable_compilation_cache(min_compile_secs=0)  # every program: eager ops and small jits add up to minutes


@pytest.fixture(scope="session")
def cartpole():
    """Classic cart-pole balance, Gymnasium's CartPole-v1."""
    import jarena

    return jarena.build_arena("classic|domain:cartpole")


@pytest.fixture(scope="session")
def pendulum():
    """Classic pendulum swing-up, Gymnasium's Pendulum-v1."""
    import jarena

    return jarena.build_arena("classic|domain:pendulum")
