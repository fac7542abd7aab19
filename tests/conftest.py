"""Test configuration: JAX's persistent compilation cache keeps the suite fast on small CPU machines."""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; also keeps dm_control from probing X11

from jarena.platform import avoid_cpu_eigen_deadlock, enable_compilation_cache

avoid_cpu_eigen_deadlock(force=True)  # before JAX starts its CPU backend
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
