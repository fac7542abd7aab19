"""Camera frames per second of MJX arenas rendered in JAX, against MuJoCo's host renderer and the physics
step.

For each domain, resolution R and batch size B, each measurement is one jitted ``lax.scan`` compiled apart
(``jit(...).lower(...).compile()``, timed), one warm-up call, then ``--repeats`` timed calls interleaved across
measurements (best shown, median in the JSON):

- ``render``: ``jax.vmap(camera.render)`` of B physics states (random poses: a reset then random actions),
  ``--frames`` frames per call (each frame of slightly moved geoms, so none is computed once for all):
  frames/s.
- ``step``: ``jarena.batch_step`` of the state-only arena (``dmc|domain:<d>,task:<t>``), ``--steps`` control
  steps per call with random actions, no resets: control steps/s.
- ``pixel-step``: the same with ``pixels:R`` (the camera sensor renders the state after every step): control
  steps/s. ``1 - step / pixel-step`` (times) is the fraction of a pixel step spent rendering.
- ``host``: the peer, ``mujoco.Renderer`` (EGL on a GPU machine, MuJoCo's default camera options) rendering
  camera 0 of ``--host-frames`` states one after another on the host, each from ``qpos`` (``mj_forward``,
  ``update_scene``, ``render``): frames/s of one renderer (one process).

Goal: at B = 4096, rendering a 64 x 64 frame costs no more than one walker control step
(``render`` frames/s >= ``step`` steps/s), and ``render`` is >= 100x ``host``.

Usage::

    python benchmarks/pixels_throughput.py --help
    python benchmarks/pixels_throughput.py --batch-sizes 1,4 --steps 2 --frames 2 --repeats 1   # CPU smoke run
    python benchmarks/pixels_throughput.py --out results/pixels_gpu.md   # GPU: B = 1 ... 8192, R = 64, 84
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time

import jax
import jax.numpy as jnp

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
import mujoco  # noqa: E402  (after jarena, which chose the headless GL backend)

from jarena.arenas.mjx import camera as camera_lib  # noqa: E402
from jarena.arenas.mjx.dynamics import model_of  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cartpole_throughput import fmt, parse_batches, write_report  # noqa: E402
from timing import environment, time_interleaved  # noqa: E402

MEASUREMENTS = ("render", "step", "pixel-step", "host")
DOMAINS = {"walker": "walk", "cartpole": "swingup", "cheetah": "run", "finger": "spin", "humanoid": "walk"}


def state_arena(domain: str):
    return jarena.build_arena(f"dmc|domain:{domain},task:{DOMAINS[domain]}")


@functools.cache  # every measurement of a (domain, B) starts from the same states: pose them once
def posed_states(domain: str, batch: int, seed: int, steps: int = 10):
    """B states of the domain's state-only arena a few random steps after reset (varied poses); the pixel
    arena's states have the same structure and physics."""
    arena = state_arena(domain)
    params = arena.default_params()

    def go(key):
        states, _ = jarena.batch_reset(arena, key, batch, params)

        def body(states, t):
            actions = jax.vmap(arena.sample_action)(jax.random.split(jax.random.fold_in(key, t), batch))
            return jarena.batch_step(arena, states, actions, params, reset_done=False)[0], None

        return jax.lax.scan(body, states, jnp.arange(steps))[0]

    return jax.block_until_ready(jax.jit(go)(jax.random.key(seed)))


def make(measurement: str, domain: str, resolution: int, batch: int, args):
    """``(run, carry, units)``: ``run(carry) -> carry`` one timed call, ``units`` counted per call."""
    arena = state_arena(domain)
    if measurement == "pixel-step":
        arena = jarena.build_arena(f"{arena.build_string},pixels:{resolution}")
    params = arena.default_params()
    states = posed_states(domain, batch, args.seed)
    if measurement in ("step", "pixel-step"):
        def run(carry):
            states, key = carry

            def body(states, t):
                actions = jax.vmap(arena.sample_action)(jax.random.split(jax.random.fold_in(key, t), batch))
                states, info = jarena.batch_step(arena, states, actions, params, reset_done=False)
                # every observation leaf is used, so that XLA cannot drop the rendering
                used = sum(jnp.mean(x.astype(jnp.float32)) for x in jax.tree_util.tree_leaves(info.observation))
                return states, info.reward.mean() + used

            states, used = jax.lax.scan(body, states, jnp.arange(args.steps))
            # the key depends on the rewards and observations, so XLA cannot drop their computation
            return states, jax.random.fold_in(key, jax.lax.bitcast_convert_type(jnp.sum(used), jnp.uint32))

        return run, (states, jax.random.key(args.seed + 1)), batch * args.steps
    scene = camera_lib.scene_of(model_of(arena.dynamics))
    data = arena.privileged(states).physics

    def run(carry):
        data, total = carry

        def body(total, t):
            moved = data.replace(geom_xpos=data.geom_xpos + 1e-4 * t.astype(jnp.float32))
            frame = jax.vmap(lambda d: camera_lib.render(scene, d, 0, resolution, resolution))(moved)
            return total + frame.depth.mean() + frame.rgb[..., 0].mean(), None

        total, _ = jax.lax.scan(body, total, jnp.arange(args.frames))
        return data, total

    return run, (data, jnp.zeros(())), batch * args.frames


def host_fps(domain: str, resolution: int, frames: int, seed: int) -> dict:
    """Frames/s of ``mujoco.Renderer`` rendering camera 0 of ``frames`` random poses, one after another."""
    model = model_of(state_arena(domain).dynamics)
    states = jax.device_get(posed_states(domain, frames, seed).physics.qpos)
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, resolution, resolution)
    try:
        for qpos in states[:2]:  # warm-up
            data.qpos[:] = qpos
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=0)
            renderer.render()
        t0 = time.perf_counter()
        for qpos in states:
            data.qpos[:] = qpos
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=0)
            renderer.render()
        seconds = time.perf_counter() - t0
    finally:
        renderer.close()
    print(f"{domain} R={resolution} host: {frames / seconds:.4g} frames/s", flush=True)
    return {"per_s": frames / seconds, "frames": frames, "seconds": seconds}


def time_batch(domain: str, resolution: int, batch: int, args) -> dict:
    makers = {m: (lambda m=m: make(m, domain, resolution, batch, args)) for m in args.measurements if m != "host"}
    return time_interleaved(makers, args.repeats, label=f"{domain} R={resolution} B={batch:6d} ")


def markdown(env: dict, rows: list[dict], hosts: dict) -> str:
    lines = [f"Device: {env['device']} ({env['backend']}), CPU {env['cpu']} x {env['cpu_count']}, Python "
             f"{env['python']}, jax {env['jax']}, mujoco {env['mujoco']} (MUJOCO_GL={env['mujoco_gl']}); "
             f"{env['date']}", f"Command: `{env['command']}`", "",
             "| domain | R | B | render frames/s | host frames/s | render / host | step steps/s | pixel-step steps/s "
             "| render share of a pixel step | render frame vs step |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        r = row["results"]
        render, step, pixel = (r.get(k, {}).get("per_s") for k in ("render", "step", "pixel-step"))
        host = hosts.get((row["domain"], row["resolution"]), {}).get("per_s")
        share = None if step is None or pixel is None else 1 - pixel / step
        cells = [row["domain"], str(row["resolution"]), str(row["batch"]), fmt(render), fmt(host),
                 "-" if render is None or host is None else f"{render / host:.0f}x", fmt(step), fmt(pixel),
                 "-" if share is None else f"{100 * share:.0f}%",
                 "-" if render is None or step is None else f"{step / render:.2f} steps"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "'render frame vs step': the time of one rendered frame in control steps of the state-only arena "
              "(<= 1 meets the goal)."]
    return "\n".join(lines) + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--domains", default="walker", help=f"comma-separated, from {list(DOMAINS)} (default walker)")
    p.add_argument("--resolutions", default="64,84", help="comma-separated image sides (default 64,84)")
    p.add_argument("--batch-sizes", type=parse_batches, default=None,
                   help="comma-separated B (default: 1,64,1024,4096,8192 on GPU, 1,4 on CPU)")
    p.add_argument("--measurements", default=",".join(MEASUREMENTS),
                   help=f"comma-separated, from {list(MEASUREMENTS)} (default: all)")
    p.add_argument("--frames", type=int, default=10, help="frames per timed call of 'render' (default 10)")
    p.add_argument("--steps", type=int, default=10, help="control steps per timed call (default 10)")
    p.add_argument("--host-frames", type=int, default=200, help="frames the host renderer draws (default 200)")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per measurement (default 3)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="write a markdown table (and JSON beside it) here")
    args = p.parse_args(argv)
    args.domains = [d.strip() for d in args.domains.split(",") if d.strip()]
    if not args.domains or set(args.domains) - set(DOMAINS):
        p.error(f"unknown domain(s) {sorted(set(args.domains) - set(DOMAINS))}; choose from {list(DOMAINS)}")
    try:
        args.resolutions = [int(r) for r in args.resolutions.split(",")]
    except ValueError:
        p.error(f"--resolutions must be comma-separated integers, got {args.resolutions!r}")
    names = [m.strip() for m in args.measurements.split(",") if m.strip()]
    unknown = sorted(set(names) - set(MEASUREMENTS))
    if unknown or not names:
        p.error(f"unknown measurement(s) {unknown}; choose from {list(MEASUREMENTS)}")
    args.measurements = names
    for key in ("frames", "steps", "host_frames", "repeats"):
        if getattr(args, key) < 1:
            p.error(f"--{key.replace('_', '-')} must be >= 1")
    if args.batch_sizes is None:
        args.batch_sizes = [1, 64, 1024, 4096, 8192] if jax.default_backend() == "gpu" else [1, 4]
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    env = environment(mujoco=mujoco.__version__, mujoco_gl=os.environ.get("MUJOCO_GL", ""))
    hosts, rows = {}, []
    for domain in args.domains:
        for resolution in args.resolutions:
            if "host" in args.measurements:
                hosts[(domain, resolution)] = host_fps(domain, resolution, args.host_frames, args.seed)
            for b in args.batch_sizes:
                rows.append({"domain": domain, "resolution": resolution, "batch": b,
                             "results": time_batch(domain, resolution, b, args)})
    table = markdown(env, rows, hosts)
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": vars(args), "rows": rows,
                                       "host": {f"{d}-{r}": v for (d, r), v in hosts.items()}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
