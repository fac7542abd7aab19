"""Shared by the throughput benchmarks: interleaved timing of compiled calls, and the machine they ran on."""

from __future__ import annotations

import datetime
import importlib.metadata
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable

import jax
from cartpole_throughput import cpu_model


def time_interleaved(makers: dict[str, Callable[[], tuple[Callable, object, int]]], repeats: int,
                     label: str = "") -> dict:
    """Times each measurement's compiled call; ``makers[name]() -> (run, carry, units)``.

    Each ``run(carry) -> carry`` is compiled apart (``jit(run).lower(carry).compile()``, timed), called once to
    warm up, then called ``repeats`` times, interleaved across measurements so that load changes weigh on all
    alike. Returns ``name -> {per_s, median_per_s, best_s, compile_s, units_per_call}`` (``units`` per best call)
    and prints one line per measurement, prefixed by ``label``.
    """
    compiled = {}
    for name, make in makers.items():
        run, carry, units = make()
        t0 = time.perf_counter()
        fn = jax.jit(run).lower(carry).compile()
        compile_s = time.perf_counter() - t0
        carry = jax.block_until_ready(fn(carry))  # warm-up
        compiled[name] = [fn, carry, units, compile_s, []]
    for _ in range(repeats):
        for entry in compiled.values():
            t0 = time.perf_counter()
            entry[1] = jax.block_until_ready(entry[0](entry[1]))
            entry[4].append(time.perf_counter() - t0)
    out = {}
    for name, (_, _, units, compile_s, times) in compiled.items():
        best = min(times)
        out[name] = {"per_s": units / best, "median_per_s": units / statistics.median(times), "best_s": best,
                     "compile_s": compile_s, "units_per_call": units}
        print(f"{label}{name:10s} {units / best:12.4g}/s  (call {best * 1e3:.1f} ms, compile {compile_s:.1f} s)",
              flush=True)
    return out


def environment(**extra) -> dict:
    """The device, host, versions, date and command of this run, plus ``extra`` entries."""
    dev = jax.devices()[0]
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "backend": jax.default_backend(), "device": dev.device_kind, "cpu": cpu_model(),
            "cpu_count": os.cpu_count(), "python": platform.python_version(), "jax": jax.__version__,
            "jaxlib": importlib.metadata.version("jaxlib"), **extra, "command": " ".join(["python"] + sys.argv)}
