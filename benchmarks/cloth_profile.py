"""One physics step of 1024 crumpled cloths, for a GPU profiler (Nsight Compute) to look inside the cloth kernels.

Crumpling the cloths runs about 250 physics steps, and under ``ncu`` every one of them is slow to launch, so the
cloths are crumpled first, without the profiler, and saved (``--save``). The profiled process loads them and runs one
``ClothPhysics.step`` (``--load``), the ``step`` measurement's step of ``benchmarks/cloth_throughput.py``: picker
closed, moving 3 mm along each axis. On an NVIDIA H200 (RESULTS.md, cloth) the profiled run took about
2 minutes, most of it ``ncu``'s start-up::

    python benchmarks/cloth_profile.py --save /tmp/cloth_states.npz
    ncu --target-processes all -k regex:_kernel -c 2 --set full -o /tmp/cloth \\
        python benchmarks/cloth_profile.py --load /tmp/cloth_states.npz
    ncu --import /tmp/cloth.ncu-rep --page details                                  # per kernel
    ncu --import /tmp/cloth.ncu-rep -k _list_kernel --page source --csv --print-source sass   # per instruction

``-k regex:_kernel -c 2`` takes the step's two Pallas kernels (the neighbour list, ``_list_kernel``, and the
substeps, ``_kernel``). ``--solver`` names a registered cloth solver (default ``fused``).
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import cloth_throughput  # noqa: E402

import jarena  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    mode = p.add_mutually_exclusive_group(required=True)
    mode.add_argument("--save", metavar="PATH", help="crumple the cloths and save their physics state here (.npz)")
    mode.add_argument("--load", metavar="PATH", help="load the cloths saved by --save and run one physics step")
    p.add_argument("--batch", type=int, default=1024, help="cloths (default 1024)")
    p.add_argument("--solver", default="fused", help="cloth solver (default fused)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.batch < 1:
        p.error("--batch must be >= 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    arena = jarena.build_arena(f"{cloth_throughput.ARENA},solver:{args.solver}")
    params = arena.default_params()

    def crumpled(key):
        return arena.privileged(jarena.batch_reset(arena, key, args.batch, params)[0]).physics

    key = jax.random.key(args.seed)
    if args.save:
        leaves = jax.tree_util.tree_leaves(jax.jit(crumpled)(key))
        np.savez(args.save, *[np.asarray(leaf) for leaf in leaves])
        print(f"saved {args.batch} crumpled cloths to {args.save}")
        return 0
    treedef = jax.tree_util.tree_structure(jax.eval_shape(crumpled, key))
    with np.load(args.load) as saved:
        leaves = [jnp.asarray(saved[f"arr_{i}"]) for i in range(len(saved.files))]
    if len(leaves) != treedef.num_leaves or leaves[0].shape[0] != args.batch:
        raise SystemExit(f"{args.load} does not hold {args.batch} cloths of {cloth_throughput.ARENA}: save them "
                         f"again with the same --batch")
    physics = jax.tree_util.tree_unflatten(treedef, leaves)
    control = cloth_throughput.step_control(args.batch, physics.picker_positions.shape[1])
    step = jax.jit(jax.vmap(arena.dynamics.step, in_axes=(0, 0, None)))
    out = step(physics, control, params.dynamics)
    print(f"stepped {args.batch} cloths: mean particle height {float(out.positions[..., 2].mean()):.4f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
