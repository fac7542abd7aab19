"""Test configuration: JAX's persistent compilation cache keeps the suite fast on small CPU machines."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; also keeps dm_control from probing X11

from jarena.platform import avoid_cpu_eigen_deadlock, enable_compilation_cache

avoid_cpu_eigen_deadlock(force=True)  # before JAX starts its CPU backend
enable_compilation_cache(min_compile_secs=0.2)  # the command line's cache, small programs too
