"""Env-steps per second of MuJoCo arenas on MJX, against raw ``mjx.step``, Brax and MuJoCo Playground.

For each environment and batch size B, every variant runs ``--steps`` control steps of B environments
with uniformly random actions in [-1, 1] inside one jitted ``lax.scan``; compilation is timed apart
(``lower(...).compile()``) and a warm-up call precedes the timed ones, which are interleaved across
variants so that load changes weigh on all alike. Variants:

- ``raw``: ``jax.vmap`` of ``n_sub_steps`` ``mjx.step`` calls on the same MuJoCo model as ours, with the
  action written to ``ctrl``: physics only (no observation, reward, termination or reset).
- ``ours``: ``jarena.batch_step``: the full arena step (observation, reward, time limit, auto-reset) with
  the arena's default auto-reset (dmc: ``lazy``, fresh initial states computed in steps where an arena
  finished; brax: ``select``).
- ``ours-repeat``: ours with ``auto_reset:repeat``: each arena restarts from its first initial state, the
  auto-reset of Brax's and Playground's training wrappers (the like-for-like comparison with them).
- ``ours-pg-options`` (dmc only): ours built with the simulation options of Playground's version of the
  model (build options ``iterations``, ``ls_iterations``, ``integrator``, ``eulerdamp``, ``timestep``,
  ``max_contact_points``, ``max_geom_pairs``): Playground trades the suite's accuracy for speed (1-4
  solver iterations, Euler instead of RK4, no implicit damping, a longer timestep for humanoid, MJX
  contact culling); this variant does the same physics work as the ``playground`` variant.
- ``ours-pg-repeat`` (dmc only): ``ours-pg-options`` with ``auto_reset:repeat``: the same physics and the
  same reset semantics as ``playground``.
- ``playground``: mujoco_playground's equivalent environment on MJX (``impl="jax"``, not Warp), with
  its Brax-training wrapper (episode length 1000, auto-reset), as Playground's trainers step it.
- ``ours-scan`` (dmc only): ours with ``differentiable:true``: the constraint solver's line search as MJX writes
  it (a fixed-length ``lax.scan`` whose steps idle once it has converged, as ``raw`` runs it) instead of ours'
  while loop (the same states, to the bit or within float32 rounding).
- ``ours-noreset``, ``ours-pg-noreset`` and ``ours-select`` (diagnostics): the arena step without
  auto-reset (suite options, Playground's options), and with the select-based auto-reset (a reset computed
  for every arena at every step) instead of the lazy one.
- ``brax``: Brax's environment (``backend="mjx"``) with ``brax.envs.training.wrap`` (episode length
  1000, auto-reset).

Usage (GPU)::

    python benchmarks/mjx_throughput.py --envs cartpole-balance,walker-walk --batch-sizes 1024,8192,32768
    python benchmarks/mjx_throughput.py --out benchmarks/mjx_results.json
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import functools
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp

try:
    import jarena
except ImportError:  # run from a checkout without installing
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena

from mujoco import mjx  # noqa: E402

import jarena.arenas.dmc.common  # noqa: E402

#: ``gpu_steps``: control steps per timed call on the GPU when ``--steps`` is not given, so that one call
#: of the suite's physics at B = 8192 takes seconds, not minutes (walker: 4e4 steps/s, humanoid: 2.5e4).
ENVS = {
    "cartpole-balance": {"ours": "dmc|domain:cartpole,task:balance", "playground": "CartpoleBalance",
                         "gpu_steps": 100},
    "walker-walk": {"ours": "dmc|domain:walker,task:walk", "playground": "WalkerWalk", "gpu_steps": 20},
    "cheetah-run": {"ours": "dmc|domain:cheetah,task:run", "playground": "CheetahRun", "gpu_steps": 100},
    "humanoid-walk": {"ours": "dmc|domain:humanoid,task:walk", "playground": "HumanoidWalk", "gpu_steps": 10},
    "ant": {"ours": "brax|env:ant,backend:mjx", "brax": "ant", "gpu_steps": 100},
}
VARIANTS = ("raw", "ours", "ours-repeat", "ours-pg-options", "ours-pg-repeat", "playground", "brax", "ours-noreset",
            "ours-select", "ours-pg-noreset", "ours-scan")
#: (ours, peer) pairs compared in the summary: like for like where the names say so.
COMPARISONS = (("ours", "ours-scan"), ("ours", "raw"), ("ours-repeat", "raw"), ("ours-noreset", "raw"),
               ("ours-repeat", "brax"), ("ours", "brax"), ("ours-pg-repeat", "playground"),
               ("ours-pg-options", "playground"), ("ours-pg-noreset", "playground"))


def _random_actions(key, t, batch, dim):
    return jax.random.uniform(jax.random.fold_in(key, t), (batch, dim), minval=-1.0, maxval=1.0)


# ---------------------------------------------------------------------------------------------- loops
# Each factory returns (init, body): init(key) -> carry (not timed); body(carry, t) -> carry.


def _playground_env(name: str):
    from mujoco_playground import registry
    return registry.load(name, config_overrides={"impl": "jax"})


def _brax_env(name: str):
    import brax.envs
    return brax.envs.get_environment(name, backend="mjx")


def ours_loop(arena_string: str, batch: int, reset: str | None = None):
    """``reset``: an ``auto_reset`` strategy to impose, ``"none"`` for no auto-reset, None for the arena's."""
    arena = jarena.build_arena(arena_string)
    if reset not in (None, "none"):
        arena = dataclasses.replace(arena, auto_reset=reset)
    params = arena.default_params()
    dim = arena.action_spec.shape[0]

    def init(key):
        states, _ = jarena.batch_reset(arena, key, batch, params)
        return states, key

    def body(carry, t):
        states, key = carry
        states, info = jarena.batch_step(arena, states, _random_actions(key, t, batch, dim), params,
                                         reset_done=(reset != "none"))
        # The next key depends on the step's rewards and observations, so that XLA computes them, as the
        # peers' loops do (their observations and rewards are in the state they carry). Earlier versions
        # did not: the oldest figures in RESULTS.md's history are of steps without observation and reward.
        used = jnp.mean(info.reward) + sum(jnp.mean(x.astype(jnp.float32))
                                           for x in jax.tree_util.tree_leaves(info.observation))
        return states, jax.random.fold_in(key, jax.lax.bitcast_convert_type(used, jnp.uint32))

    return init, body


def raw_loop(env: str, batch: int):
    """``mjx.step`` on the model our arena uses, ``n_sub_steps`` times per control step."""
    if "brax" in ENVS[env]:
        benv = _brax_env(ENVS[env]["brax"])
        model, substeps = benv.sys.mj_model, int(benv._n_frames)
    else:
        arena = jarena.build_arena(ENVS[env]["ours"])
        model = arena.dynamics.render.model
        substeps = int(round(arena.dynamics.timestep / model.opt.timestep))
    m = mjx.put_model(model)
    dim = model.nu

    def init(key):
        d = mjx.forward(m, mjx.make_data(m))
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch,) + x.shape), d), key

    def physics(d, u):
        d = d.replace(ctrl=u)
        return jax.lax.fori_loop(0, substeps, lambda _, d: mjx.step(m, d), d)

    def body(carry, t):
        data, key = carry
        return jax.vmap(physics)(data, _random_actions(key, t, batch, dim)), key

    return init, body


def playground_loop(env: str, batch: int):
    from mujoco_playground import wrapper
    penv = _playground_env(ENVS[env]["playground"])
    wrapped = wrapper.wrap_for_brax_training(penv, episode_length=1000, action_repeat=1)
    return _wrapped_loop(wrapped, penv.action_size, batch)


def brax_loop(env: str, batch: int):
    from brax.envs import training
    benv = _brax_env(ENVS[env]["brax"])
    wrapped = training.wrap(benv, episode_length=1000, action_repeat=1)
    return _wrapped_loop(wrapped, benv.action_size, batch)


def _wrapped_loop(wrapped, dim: int, batch: int):
    """A Brax-style batched env (``reset(keys)``, ``step(state, actions)``, auto-resetting) as (init, body)."""
    def init(key):
        return wrapped.reset(jax.random.key_data(jax.random.split(key, batch))), key  # raw uint32 keys

    def body(carry, t):
        state, key = carry
        return wrapped.step(state, _random_actions(key, t, batch, dim)), key

    return init, body


@functools.cache  # each ours-pg-* variant asks; loading Playground's env and our arena once is enough
def playground_options(env: str) -> str:
    """Build options that give our arena the simulation options of Playground's model of ``env``."""
    import mujoco
    model = _playground_env(ENVS[env]["playground"]).mj_model
    integrator = {int(v): k for k, v in jarena.arenas.dmc.common.INTEGRATORS.items()}[int(model.opt.integrator)]
    eulerdamp = not (model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP))
    options = (f"iterations:{model.opt.iterations},ls_iterations:{model.opt.ls_iterations},integrator:{integrator},"
               f"eulerdamp:{str(eulerdamp).lower()},timestep:{float(model.opt.timestep)!r}")
    for name in jarena.arenas.dmc.common.CONTACT_LIMITS:  # MJX contact culling, where Playground's model sets it
        index = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
        if index >= 0:
            options += f",{name}:{int(model.numeric_data[model.numeric_adr[index]])}"
    ours = jarena.build_arena(ENVS[env]["ours"]).dynamics.render.model
    touch = int(mujoco.mjtSensor.mjSENS_TOUCH)
    if touch in ours.sensor_type and touch not in model.sensor_type:  # humanoid: Playground drops them
        options += ",touch_sensors:false"
    return options


#: Our variants: (build-string suffix maker, auto-reset imposed).
OURS = {
    "ours": (lambda env: "", None),
    "ours-repeat": (lambda env: ",auto_reset:repeat", None),
    "ours-pg-options": (lambda env: "," + playground_options(env), None),
    "ours-pg-repeat": (lambda env: "," + playground_options(env) + ",auto_reset:repeat", None),
    "ours-noreset": (lambda env: "", "none"),
    "ours-pg-noreset": (lambda env: "," + playground_options(env), "none"),
    "ours-select": (lambda env: "", "select"),
    "ours-scan": (lambda env: ",differentiable:true", None),
}


def make_loop(variant: str, env: str, batch: int) -> tuple[Callable, Callable]:
    if variant in OURS:
        suffix, reset = OURS[variant]
        return ours_loop(ENVS[env]["ours"] + suffix(env), batch, reset)
    return {"raw": raw_loop, "playground": playground_loop, "brax": brax_loop}[variant](env, batch)


def applicable(variant: str, env: str) -> bool:
    if variant in ("playground", "ours-pg-options", "ours-pg-repeat", "ours-pg-noreset"):
        return "playground" in ENVS[env]
    if variant == "brax":
        return "brax" in ENVS[env]
    if variant == "ours-scan":
        return ENVS[env]["ours"].startswith("dmc|")
    return True


# ---------------------------------------------------------------------------------------------- timing


def compile_variant(variant: str, env: str, batch: int, steps: int, dump_hlo: str | None = None) -> dict:
    init, body = make_loop(variant, env, batch)

    def run(carry):
        return jax.lax.scan(lambda c, t: (body(c, t), None), carry, jnp.arange(steps, dtype=jnp.int32))[0]

    carry = jax.block_until_ready(jax.jit(init)(jax.random.key(0)))
    t0 = time.perf_counter()
    compiled = jax.jit(run).lower(carry).compile()
    compile_s = time.perf_counter() - t0
    if dump_hlo:
        os.makedirs(dump_hlo, exist_ok=True)
        with open(os.path.join(dump_hlo, f"{env}-{variant}-{batch}.hlo.txt"), "w") as f:
            f.write(compiled.as_text())
    jax.block_until_ready(compiled(carry))  # warm-up
    return {"compiled": compiled, "carry": carry, "compile_s": compile_s}


def time_env(env: str, variants: list[str], batch: int, steps: int, repeats: int, dump_hlo: str | None = None
             ) -> list[dict]:
    progs, rows = {}, []
    for v in variants:
        if not applicable(v, env):
            continue
        try:
            progs[v] = compile_variant(v, env, batch, steps, dump_hlo)
            print(f"  {env} B={batch} {v}: compiled in {progs[v]['compile_s']:.1f} s", flush=True)
        except Exception as e:  # a peer that fails to build is reported, not fatal
            rows.append({"env": env, "variant": v, "batch": batch, "error": f"{type(e).__name__}: {e}"[:300]})
            print(f"  {env} {v} B={batch}: {rows[-1]['error']}", flush=True)
    times = {v: [] for v in progs}
    for _ in range(repeats):
        for v, p in progs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(p["compiled"](p["carry"]))
            times[v].append(time.perf_counter() - t0)
    for v in progs:
        best, median = min(times[v]), statistics.median(times[v])
        rows.append({"env": env, "variant": v, "batch": batch, "steps": steps, "compile_s": progs[v]["compile_s"],
                     "best_s": best, "median_s": median, "steps_per_s": batch * steps / best})
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: steps/s per variant, and ours' ratios to raw, Playground and Brax."""
    out = ["| env | B | variant | env-steps/s | compile s | ours / this |", "|---|---:|---|---:|---:|---:|"]
    ok = [r for r in rows if "error" not in r]
    for r in ok:
        ours = next((o for o in ok if o["env"] == r["env"] and o["batch"] == r["batch"] and o["variant"] == "ours"),
                    None)
        ratio = "" if ours is None or r["variant"] == "ours" else f"{ours['steps_per_s'] / r['steps_per_s']:.2f}"
        out.append(f"| {r['env']} | {r['batch']} | {r['variant']} | {r['steps_per_s']:.3g} | {r['compile_s']:.1f} "
                   f"| {ratio} |")
    for r in rows:
        if "error" in r:
            out.append(f"| {r['env']} | {r['batch']} | {r['variant']} | error: {r['error'][:80]} | | |")
    rate = {(r["env"], r["batch"], r["variant"]): r["steps_per_s"] for r in ok}
    pairs = [(e, b, a, p) for (e, b) in dict.fromkeys((r["env"], r["batch"]) for r in ok) for a, p in COMPARISONS
             if (e, b, a) in rate and (e, b, p) in rate]
    if pairs:
        out += ["", "| env | B | ratio | value |", "|---|---:|---|---:|"]
        out += [f"| {e} | {b} | {a} / {p} | {rate[e, b, a] / rate[e, b, p]:.2f} |" for e, b, a, p in pairs]
    return "\n".join(out)


def main(argv=None) -> None:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", default=",".join(ENVS), help=f"comma-separated subset of {', '.join(ENVS)}")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"subset of {', '.join(VARIANTS)}")
    parser.add_argument("--batch-sizes", default=None, help="comma-separated (default: 1024,8192,32768 on GPU, 16 "
                        "on CPU)")
    parser.add_argument("--steps", type=int, default=None, help="control steps per timed call (default on GPU: "
                        "per env, 100 for cartpole, cheetah and ant, 20 walker, 10 humanoid; 5 on CPU)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=None, help="write rows and machine info as JSON here")
    parser.add_argument("--dump-hlo", default=None, metavar="DIR", help="write each compiled program's optimised "
                        "HLO to DIR/<env>-<variant>-<B>.hlo.txt")
    args = parser.parse_args(argv)
    gpu = jax.default_backend() != "cpu"
    batches = [int(b) for b in (args.batch_sizes or ("1024,8192,32768" if gpu else "16")).split(",")]
    steps_for = {e: args.steps or (ENVS[e]["gpu_steps"] if gpu else 5) for e in ENVS}
    envs, variants = args.envs.split(","), args.variants.split(",")
    for e in envs:
        if e not in ENVS:
            parser.error(f"unknown env {e!r}; choose from {', '.join(ENVS)}")
    for v in variants:
        if v not in VARIANTS:
            parser.error(f"unknown variant {v!r}; choose from {', '.join(VARIANTS)}")
    device = str(jax.devices()[0].device_kind)
    print(f"# MJX throughput on {device} ({jax.default_backend()}), jax {jax.__version__}, steps per call: "
          + ", ".join(f"{e} {steps_for[e]}" for e in envs), flush=True)
    rows = []
    for env in envs:
        for b in batches:
            new = time_env(env, variants, b, steps_for[env], args.repeats, args.dump_hlo)
            rows += new
            for r in new:
                if "error" not in r:
                    print(f"  {env:16s} B={b:6d} {r['variant']:17s} {r['steps_per_s']:12.4g} steps/s "
                          f"(compile {r['compile_s']:.1f} s)", flush=True)
    print(table(rows))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"device": device, "backend": jax.default_backend(), "jax": jax.__version__,
                       "python": platform.python_version(), "date": datetime.date.today().isoformat(),
                       "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
