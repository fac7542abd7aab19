"""Pick-and-place actions and cloth physics steps per second, with 128 x 128 observations.

The measurements, each one jitted ``lax.scan`` for a batch of B cloths, compiled apart
(``jit(...).lower(...).compile()``, timed), one warm-up call, then ``--repeats`` timed calls interleaved across
the measurements (best shown, median in the JSON):

- ``act``: the benchmark arena ``cloth|domain:square_fabric,initial:crumpled,action:pixel_pick_and_place(1),
  task:flattening`` (40 x 40 particles, 128 x 128 ``rgb``, ``depth`` and ``mask``), ``--actions`` actions per
  call of ``jarena.batch_step`` without resets, uniform random pick and place points. Reported: actions/s
  (``B x actions / seconds``) and the physics steps they contain (one action = ``tool.substeps`` = 68 steps).
- ``act+reset``: the same with auto-reset (``lazy``) and episodes of ``--horizon`` actions, so that one
  crumpled reset (about 250 physics steps, simulated on device) falls into every ``horizon`` actions.
- ``physics``: ``ClothPhysics.step`` alone (``--substeps``, default 8, self-collision, no task, no camera), ``--steps``
  steps per call with random picker controls, reported as physics steps/s.
- ``step``: ``ClothPhysics.step`` alone, ``--steps`` steps per call, every one from the same crumpled state (nudged by
  1e-9 m per step, so that XLA computes each) with the picker closed and moving 3 mm along each axis: every step
  reads the same neighbour lists, so two versions of the kernels compare on the same work even where they change
  the physics (reported as physics steps/s).
- ``render``: the top-down camera alone (``camera.render`` at 128 x 128) of the cloths' current particles,
  ``--frames`` renders per call (frames/s).

The peer, SoftGym (NVIDIA FleX), cannot be installed here (it needs a patched FleX build and Docker). Its
reported rate: about 55 environment steps per second headless, with a 40-particle cloth and no rendering, on an
RTX 3080 (SoftGym issue #47, github.com/Xingyu-Lin/softgym/issues/47), one cloth per process; one SoftGym
environment step is ``action_repeat`` = 8 FleX steps, so about 440 FleX steps/s, and one pick-and-place
(50-250 FleX steps, ``../shared/reference/softgym_cloth.md``) takes 0.1-0.6 s: 2-9 actions per second per
process. The table's ratio column divides by the upper end, 9 actions/s (and 440 steps/s for ``physics``).

Usage::

    python benchmarks/cloth_throughput.py --help
    python benchmarks/cloth_throughput.py --batch-sizes 1,4 --actions 2 --steps 8 --repeats 1   # CPU smoke run
    python benchmarks/cloth_throughput.py --out results/cloth_gpu.md        # GPU: B = 1, 64, 1024, 4096
    python benchmarks/cloth_throughput.py --solvers xla,fused --batch-sizes 1024   # the two solvers side by side
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
from jarena.arenas.cloth import camera as camera_lib  # noqa: E402
from jarena.arenas.cloth.physics import SOLVERS  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cartpole_throughput import fmt, parse_batches, write_report  # noqa: E402
from timing import environment, time_interleaved  # noqa: E402

ARENA = "cloth|domain:square_fabric,initial:crumpled,task:flattening"
TOOL = "pixel_pick_and_place(1)"
MEASUREMENTS = ("act", "act+reset", "physics", "step", "render")
SOFTGYM_ACTIONS_PER_S = 9.0  # upper end of SoftGym's per-process rate, see the module docstring
SOFTGYM_STEPS_PER_S = 440.0


def step_control(batch: int, num_pickers: int) -> jax.Array:
    """float32 (batch, num_pickers, 4): the ``step`` measurement's picker control, closed and moving 3 mm along
    each axis."""
    return jnp.concatenate([jnp.full((batch, num_pickers, 3), 0.003), jnp.ones((batch, num_pickers, 1))], axis=-1)


def make(measurement: str, batch: int, solver: str, args, reset_solver: str | None = None):
    """Returns ``(run, carry, units)``: ``run(carry) -> carry`` one timed call, ``units`` counted per call.

    ``reset_solver``: the solver that crumples the starting cloths (untimed; default ``solver``), so that
    measurements of several solvers can start from the same cloths."""
    def build(solver):
        return jarena.build_arena(f"{ARENA},action:{args.tool},resolution:{args.resolution},horizon:{args.horizon},"
                                  f"solver:{solver},substeps:{args.substeps}")

    arena = build(solver)
    params = arena.default_params()
    starts = arena if reset_solver is None else build(reset_solver)
    states, _ = jax.jit(lambda k: jarena.batch_reset(starts, k, batch, params))(jax.random.key(args.seed))
    jax.block_until_ready(states)
    if measurement in ("act", "act+reset"):
        reset_done = measurement == "act+reset"
        size = arena.action_spec.shape[0]

        def run(carry):
            states, key = carry

            def body(states, t):
                actions = jax.random.uniform(jax.random.fold_in(key, t), (batch, size), minval=-1.0, maxval=1.0)
                states, info = jarena.batch_step(arena, states, actions, params, reset_done=reset_done)
                used = sum(jnp.mean(x.astype(jnp.float32)) for x in jax.tree_util.tree_leaves(info.observation))
                return states, info.reward.mean() + used

            states, used = jax.lax.scan(body, states, jnp.arange(args.actions))
            # the key depends on the rewards and observations, so XLA cannot drop their computation
            return states, jax.random.fold_in(key, jax.lax.bitcast_convert_type(jnp.sum(used), jnp.uint32))

        return run, (states, jax.random.key(args.seed + 1)), batch * args.actions
    physics_states = arena.privileged(states).physics
    if measurement == "physics":
        dynamics = arena.dynamics
        k = physics_states.picker_positions.shape[1]

        def run(carry):
            physics, key = carry

            def body(physics, t):
                move = jax.random.uniform(jax.random.fold_in(key, t), (batch, k, 3), minval=-0.01, maxval=0.01)
                control = jnp.concatenate([move, jnp.ones((batch, k, 1))], axis=-1)
                return jax.vmap(dynamics.step, in_axes=(0, 0, None))(physics, control, params.dynamics), None

            physics, _ = jax.lax.scan(body, physics, jnp.arange(args.steps))
            return physics, jax.random.fold_in(key, 1)

        return run, (physics_states, jax.random.key(args.seed + 2)), batch * args.steps
    if measurement == "step":
        dynamics = arena.dynamics
        k = physics_states.picker_positions.shape[1]
        control = step_control(batch, k)

        def run(carry):
            physics, total = carry

            def body(total, t):
                nudged = physics.replace(positions=physics.positions + 1e-9 * t.astype(jnp.float32))
                out = jax.vmap(dynamics.step, in_axes=(0, 0, None))(nudged, control, params.dynamics)
                return total + out.positions[:, 0, 0].sum(), None

            total, _ = jax.lax.scan(body, total, jnp.arange(args.steps))
            return physics, total

        return run, (physics_states, jnp.zeros(())), batch * args.steps
    camera = jax.tree_util.tree_map(jnp.float32, camera_lib.CameraParams())
    mesh = physics_states.mesh

    def run(carry):
        positions, total = carry

        def body(total, t):
            shifted = positions + 1e-4 * t.astype(jnp.float32)
            image = jax.vmap(lambda x: camera_lib.render(x, mesh, camera, args.resolution))(shifted)
            return total + image["depth"].mean(), None

        total, _ = jax.lax.scan(body, total, jnp.arange(args.frames))
        return positions, total

    return run, (physics_states.positions, jnp.zeros(())), batch * args.frames


def time_batch(batch: int, solver: str, args) -> dict:
    measurements = [m for m in args.measurements if m != "render" or solver == args.solvers[0]]
    return time_interleaved({m: (lambda m=m: make(m, batch, solver, args)) for m in measurements}, args.repeats,
                            label=f"B={batch:6d} {solver} ")


def markdown(env: dict, rows: list[dict], args) -> str:
    steps_per_action = jarena.build_arena(f"{ARENA},action:{args.tool}").tool.substeps
    lines = [f"Device: {env['device']} ({env['backend']}), CPU {env['cpu']} x {env['cpu_count']}, Python "
             f"{env['python']}, jax {env['jax']}; {env['date']}", f"Command: `{env['command']}`", "",
             f"One action = {steps_per_action} physics steps ({args.substeps} substeps each), 40 x 40 particles, "
             f"{args.resolution} x {args.resolution} observations. Ratio: against SoftGym's ~"
             f"{SOFTGYM_ACTIONS_PER_S:g} actions/s ({SOFTGYM_STEPS_PER_S:g} FleX steps/s) per process.", "",
             "| B | solver | actions/s (act) | physics steps/s in act | actions/s (act+reset) "
             "| physics steps/s (physics) | physics steps/s (step) | frames/s (render) | act vs SoftGym |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        r = row["results"]
        act = r.get("act", {}).get("per_s")
        cells = [fmt(act), fmt(None if act is None else act * steps_per_action),
                 fmt(r.get("act+reset", {}).get("per_s")), fmt(r.get("physics", {}).get("per_s")),
                 fmt(r.get("step", {}).get("per_s")), fmt(r.get("render", {}).get("per_s")),
                 "-" if act is None else f"{act / SOFTGYM_ACTIONS_PER_S:.0f}x"]
        lines.append(f"| {row['batch']} | {row['solver']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch-sizes", type=parse_batches, default=None,
                   help="comma-separated B (default: 1,64,1024,4096 on GPU, 1,4 on CPU)")
    p.add_argument("--measurements", default=",".join(MEASUREMENTS),
                   help=f"comma-separated, from {list(MEASUREMENTS)} (default: all)")
    p.add_argument("--actions", type=int, default=4, help="actions per timed call (default 4)")
    p.add_argument("--steps", type=int, default=68,
                   help="physics steps per timed call of 'physics' and 'step' (default 68)")
    p.add_argument("--frames", type=int, default=8, help="renders per timed call of 'render' (default 8)")
    p.add_argument("--horizon", type=int, default=30, help="actions per episode for act+reset (default 30)")
    p.add_argument("--resolution", type=int, default=128, help="camera resolution (default 128)")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per measurement (default 3)")
    p.add_argument("--solvers", default="auto",
                   help=f"comma-separated cloth solvers to time side by side, from {['auto', *SOLVERS]} "
                        "(default auto: the fused kernel on a GPU)")
    p.add_argument("--substeps", type=int, default=8, help="XPBD substeps per physics step (default 8, the arena's)")
    p.add_argument("--tool", default=TOOL,
                   help=f"the arena's action tool (default {TOOL}); e.g. pixel_pick_and_place(1,4,16,4,12): phases "
                        "of lift 4, carry 16, lower 4 and settle 12 steps (40 steps per action instead of 68)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="write a markdown table (and JSON beside it) here")
    args = p.parse_args(argv)
    names = [m.strip() for m in args.measurements.split(",") if m.strip()]
    unknown = sorted(set(names) - set(MEASUREMENTS))
    if unknown or not names:
        p.error(f"unknown measurement(s) {unknown}; choose from {list(MEASUREMENTS)}")
    args.measurements = names
    args.solvers = [v.strip() for v in args.solvers.split(",") if v.strip()]
    bad = sorted(set(args.solvers) - {"auto", *SOLVERS})
    if bad or not args.solvers:
        p.error(f"unknown solver(s) {bad}; choose from {['auto', *SOLVERS]}")
    for key in ("actions", "steps", "frames", "horizon", "repeats", "substeps"):
        if getattr(args, key) < 1:
            p.error(f"--{key} must be >= 1")
    if args.batch_sizes is None:
        args.batch_sizes = [1, 64, 1024, 4096] if jax.default_backend() == "gpu" else [1, 4]
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    env = environment()
    rows = [{"batch": b, "solver": v, "results": time_batch(b, v, args)}
            for b in args.batch_sizes for v in args.solvers]
    table = markdown(env, rows, args)
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "args": vars(args), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
