"""Two or more versions of the cloth kernels (`jarena/arenas/cloth/fused.py`) side by side: same bits? how fast?

Each version is a copy of ``fused.py`` (for instance one from another git revision: ``git show
REV:jarena/arenas/cloth/fused.py > /tmp/fused_rev.py``), loaded as its own module and registered as a cloth
solver of its own (``solver:<name>``), with its list kernel and its substeps kernel. Then, in one process:

1. **Bits.** ``--bits-batch`` crumpled cloths of the benchmark arena (crumpled by ``solver:auto``, the same for
   every version) take one random pick-and-place under each version; the final particle positions are compared
   with the first version's (identical to the bit, or the largest difference in metres).
2. **Speed.** ``benchmarks/cloth_throughput.py``'s measurements (``step``, ``physics``, ``act``; see its
   docstring) at batch ``--batch``, from the same crumpled cloths (crumpled by ``solver:auto``), every version
   compiled apart and the timed calls interleaved across versions, so that load changes weigh on all alike (best
   of ``--repeats``, median in the JSON).

Usage (on a GPU; on a CPU the kernels run in Pallas' interpreter, which is only good for a smoke run)::

    git show main:jarena/arenas/cloth/fused.py > /tmp/fused_main.py
    python benchmarks/cloth_kernels_ab.py --kernels main=/tmp/fused_main.py,new=jarena/arenas/cloth/fused.py
    python benchmarks/cloth_kernels_ab.py --kernels a=/tmp/a.py,b=/tmp/b.py --measurements step --batch 1024
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import sys

import jax
import numpy as np

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
from jarena.arenas.cloth import collision, physics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cloth_throughput  # noqa: E402
from cartpole_throughput import fmt, write_report  # noqa: E402
from timing import environment, time_interleaved  # noqa: E402

MEASUREMENTS = ("step", "physics", "act")
NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def load_kernels(name: str, path: str) -> physics.Solver:
    """The module at ``path`` (a version of ``fused.py``) as a cloth solver, registered as ``name``.

    Versions before ``neighbour_rows`` took the list as (N, M) and each pair's share from the caller: they get both."""
    spec = importlib.util.spec_from_file_location(f"cloth_kernels_{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    if hasattr(module, "neighbour_rows"):
        solver = physics.Solver(module.neighbour_rows, module.run_substeps)
    else:
        def substeps(mesh, count, x, v, inv_mass, *rest):
            *rest, neighbours, scalars = rest
            return module.run_substeps(mesh, count, x, v, inv_mass, *rest, neighbours,
                                       collision.pair_shares(inv_mass, neighbours), scalars)

        solver = physics.Solver(module.neighbour_list, substeps)
    physics.SOLVERS[name] = solver
    return solver


def crumpled_starts(batch: int, seed: int):
    """``batch`` crumpled cloths of the benchmark arena, crumpled once by ``solver:auto`` for every version."""
    arena = jarena.build_arena(f"{cloth_throughput.ARENA},solver:auto")
    params = arena.default_params()
    states, _ = jax.jit(lambda k: jarena.batch_reset(arena, k, batch, params))(jax.random.key(seed))
    return states


def final_positions(solver: str, states, seed: int) -> np.ndarray:
    """Particle positions (B, N, 3) of the cloths ``states`` after one random pick-and-place with ``solver``."""
    arena = jarena.build_arena(f"{cloth_throughput.ARENA},solver:{solver}")
    params = arena.default_params()
    batch = arena.privileged(states).physics.positions.shape[0]
    actions = jax.random.uniform(jax.random.key(seed + 1), (batch, arena.action_spec.shape[0]), minval=-1.0,
                                 maxval=1.0)
    states, _ = jax.jit(lambda s, a: jarena.batch_step(arena, s, a, params))(states, actions)
    return np.asarray(arena.privileged(states).physics.positions)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kernels", default="current=" + os.path.join("jarena", "arenas", "cloth", "fused.py"),
                   help="comma-separated NAME=PATH, each a version of fused.py (names: lower case, digits, _); "
                        "the first is the reference for the bits (default: current=jarena/arenas/cloth/fused.py)")
    p.add_argument("--measurements", default=",".join(MEASUREMENTS),
                   help=f"comma-separated, from {list(MEASUREMENTS)} (default: all)")
    p.add_argument("--batch", type=int, default=1024, help="cloths per timed call (default 1024)")
    p.add_argument("--bits-batch", type=int, default=64, help="cloths compared for the bits (default 64; 0: skip)")
    p.add_argument("--steps", type=int, default=68, help="physics steps per timed call of step and physics")
    p.add_argument("--actions", type=int, default=2, help="actions per timed call of act (default 2)")
    p.add_argument("--repeats", type=int, default=4, help="timed calls per version and measurement (default 4)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="write a markdown table (and JSON beside it) here")
    args = p.parse_args(argv)
    kernels = {}
    for item in (part.strip() for part in args.kernels.split(",") if part.strip()):
        name, sep, path = item.partition("=")
        if not sep or not NAME.match(name):
            p.error(f"--kernels takes NAME=PATH with NAME of lower-case letters, digits and _, got {item!r}")
        if name in kernels or name in physics.SOLVERS or name == "auto":
            p.error(f"kernel name {name!r} is taken; names in use: {sorted({*kernels, *physics.SOLVERS, 'auto'})}")
        if not os.path.isfile(path):
            p.error(f"no such file for kernels {name!r}: {path}")
        kernels[name] = path
    if not kernels:
        p.error("--kernels names no version")
    args.kernels = kernels
    args.measurements = [m.strip() for m in args.measurements.split(",") if m.strip()]
    unknown = sorted(set(args.measurements) - set(MEASUREMENTS))
    if unknown or not args.measurements:
        p.error(f"unknown measurement(s) {unknown}; choose from {list(MEASUREMENTS)}")
    for key in ("batch", "steps", "actions", "repeats"):
        if getattr(args, key) < 1:
            p.error(f"--{key.replace('_', '-')} must be >= 1")
    if args.bits_batch < 0:
        p.error("--bits-batch must be >= 0")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    for name, path in args.kernels.items():
        load_kernels(name, path)
    env = environment()
    names = list(args.kernels)
    bits = {}
    if args.bits_batch:
        starts = crumpled_starts(args.bits_batch, args.seed)
        reference = final_positions(names[0], starts, args.seed)
        for name in names:
            x = reference if name == names[0] else final_positions(name, starts, args.seed)
            bits[name] = {"identical": bool(np.array_equal(x, reference)),
                          "max_difference_m": float(np.abs(x - reference).max())}
            print(f"bits {name}: identical to {names[0]}: {bits[name]['identical']} "
                  f"(largest difference {bits[name]['max_difference_m']:.3g} m)", flush=True)
    throughput_args = cloth_throughput.parse_args(["--steps", str(args.steps), "--actions", str(args.actions),
                                                   "--seed", str(args.seed)])
    timings = {m: time_interleaved({name: (lambda m=m, name=name: cloth_throughput.make(
        m, args.batch, name, throughput_args, reset_solver="auto")) for name in names}, args.repeats, label=f"{m} ")
        for m in args.measurements}
    units = {"step": "physics steps/s", "physics": "physics steps/s", "act": "actions/s"}
    lines = [f"Device: {env['device']} ({env['backend']}), Python {env['python']}, jax {env['jax']}; {env['date']}",
             f"Command: `{env['command']}`", "", f"B = {args.batch} crumpled 40 x 40 cloths; bits: "
             f"{args.bits_batch} cloths after one random pick-and-place, against `{names[0]}`.", "",
             "| kernels | file | same bits | " + " | ".join(f"{m} ({units[m]})" for m in args.measurements) + " |",
             "|---|---|---|" + "---:|" * len(args.measurements)]
    for name in names:
        same = "-" if name not in bits else ("yes" if bits[name]["identical"] else
                                              f"no ({bits[name]['max_difference_m']:.2g} m)")
        cells = [fmt(timings[m][name]["per_s"]) for m in args.measurements]
        lines.append(f"| {name} | `{args.kernels[name]}` | {same} | " + " | ".join(cells) + " |")
    table = "\n".join(lines) + "\n"
    print(table)
    if args.out:
        write_report(args.out, table, {"environment": env, "kernels": args.kernels, "bits": bits,
                                       "timings": timings})
    return 0


if __name__ == "__main__":
    sys.exit(main())
