"""A cloth control step as two fused GPU kernels (Pallas, Triton backend): the neighbour search and the substeps.

:meth:`.physics.ClothPhysics.step` prepares what is constant over a control step (grasp, neighbour list,
tethers) and then runs ``substeps`` XPBD substeps. Written as jax.numpy, each substep is some forty XLA
kernels that read and write every particle array in GPU memory; here one kernel program runs every substep
of one cloth, its arrays in registers and its few shared arrays in the L1/L2 caches, and ``vmap`` gives one
program per cloth. The arithmetic is the jax.numpy solver's (:func:`.physics.substeps_xla`), operation for
operation and in the same order, so the two agree to float rounding (``tests/arenas/cloth/test_fused.py``), but
for three rewrites that save instructions (this kernel is bound by issuing them) and give the same bits on an
NVIDIA GPU (``benchmarks/cloth_kernels_ab.py``): a constraint pair's two moves as one, the self-collision's crowd
relief per particle rather than per pair, and the contact normal as the difference times one reciprocal of the
distance (on an H200 the same bits as three divisions, Triton's division being an approximate one; in the CPU
interpreter they round apart).

How a program shares positions between its threads: Gauss-Seidel constraint passes, tethers and the
self-collision read other particles' positions, so before each such read every thread stores its particles
to a scratch array and waits at a barrier (``__syncthreads``), and waits again before the next store. Each
particle reads its role and partner in a constraint colour from a table (:func:`colour_roles`; reading it costs
fewer instructions than finding them from the grid coordinates, and this kernel is bound by issuing instructions),
and moves only itself, so no pass scatters.

The neighbour search (:func:`neighbour_list`) takes the particles sorted by hashed cell from XLA, and runs in two
kernels. In the walk, programs of :data:`LIST_BLOCK` particles (one warp each), dealt the cloth's particles busiest
first, walk for each of their particles the candidates its 27 cells hold (but cells wholly beyond the radius), one
candidate per iteration, so that a program iterates as often as its own busiest particle has candidates (a crumpled
cloth's busiest particle has about twice the average; one program per cloth iterated that often for every particle),
keep those within the radius with their distances, and count them within each reach of :data:`.collision.REACH`.
The listing, one program per cloth, lists the pairs under both particles' reach: the pairs of
:func:`.collision.neighbour_list` in the same order, without its cap on candidates. Which program walks a particle
changes nothing in what it finds, so the deal changes the time and not the bits.

On a CPU the kernel runs in Pallas' interpreter (for tests; slow), where barriers are not needed.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plgpu

from jarena.arenas.cloth import collision
from jarena.arenas.cloth.collision import RELAXATION
from jarena.arenas.cloth.mesh import ClothMesh

SCALARS = ("alpha_stretch", "alpha_shear", "alpha_bend", "decay", "fall", "h", "particle_radius", "friction",
           "collision_distance", "self_friction")
"""Per-cloth float32 scalars the kernel reads, in order (then the pickers' start and end positions): XPBD
compliances over h^2, velocity decay per substep, gravity's velocity change per substep (m/s, negative),
substep length (s), floor distance (m), floor friction, self-collision distance (m), self friction."""


def padded_size(n: int) -> int:
    """Particles per kernel program: the next power of 2 (Triton's arrays have power-of-2 shapes)."""
    return 1 << max(4, (int(n) - 1).bit_length())


def default_warps(n_pad: int) -> int:
    """Warps per kernel program for ``n_pad`` padded particles: two particles per thread, 4 to 32 warps.

    The programs are register-bound: with more particles per thread they hold fewer threads per GPU core to hide
    their memory latency. For 40 x 40 cloths (2048 padded) 32 warps step 20% more actions per second than the
    16 (list) and 8 (substeps) used before, on an H100 and an H200 alike (``benchmarks/RESULTS.md``); the
    warps split the same arithmetic among threads, so the results are the same bits.
    """
    return min(32, max(4, int(n_pad) // 64))


COLOURS = np.array([  # (di, dj, axis, div, colour, kind): the 12 constraint colours, in their order of solving
    (di, dj, axis, div, colour, kind)
    for di, dj, axis, div, kind in [(0, 1, 1, 1, 0), (1, 0, 0, 1, 0), (1, 1, 0, 1, 1), (1, -1, 0, 1, 1),
                                    (0, 2, 1, 2, 2), (2, 0, 0, 2, 2)]
    for colour in (0, 1)], np.int32)
"""Constraint colours: pair ``(i, j) - (i + di, j + dj)`` belongs to a colour if ``((i, j)[axis] // div) % 2 ==
colour`` for its first particle; ``kind`` 0, 1, 2: stretch, shear, bend (:data:`KINDS`). Both solvers
solve these (:func:`.physics._constraint_pairs` builds its pair masks from them)."""
KINDS = ("stretch", "shear", "bend")


@functools.cache
def colour_roles(mesh: ClothMesh) -> np.ndarray:
    """int32 (len(COLOURS) x padded_size(N),): each particle's role in each colour, ``4 x partner + first + 2 x
    second`` (first: the pair's first particle; second: its second; partner: the other particle, the particle itself
    clipped into the grid where it has no pair). A table read once per pass instead of the grid arithmetic of
    :func:`_first_of_pair` (the same partners, so the same bits)."""
    n, n_pad = mesh.num_particles, padded_size(mesh.num_particles)
    p = np.arange(n_pad)
    i, j = p // mesh.cols, p % mesh.cols
    inside = p < n
    roles = []
    for di, dj, axis, div, colour, _ in COLOURS.tolist():
        first = inside & np.asarray(_first_of_pair(i, j, di, dj, axis, div, colour, mesh.rows, mesh.cols))
        fi, fj = i - di, j - dj
        second = inside & (fi >= 0) & (fj >= 0) & (fj < mesh.cols) & np.asarray(
            _first_of_pair(fi, fj, di, dj, axis, div, colour, mesh.rows, mesh.cols))
        step = di * mesh.cols + dj
        partner = np.clip(np.where(first, p + step, np.where(second, p - step, p)), 0, n - 1)
        roles.append(4 * partner + first + 2 * second)
    return np.concatenate(roles).astype(np.int32)


def _first_of_pair(i, j, di, dj, axis, div, colour, rows, cols):
    """bool: particle ``(i, j)`` is the first particle of a pair of this colour."""
    along = i if axis == 0 else j
    return (i + di < rows) & (j + dj >= 0) & (j + dj < cols) & ((along // div) % 2 == colour)


def _kernel(scal_ref, colours_ref, roles_ref, xv_ref, inv_mass_ref, holder_ref, offset_ref, tether_to_ref,
            tether_len_ref, neighbours_ref, share_ref,
            out_ref, x_s, prev_s, touch_s, *,
            mesh: ClothMesh, n_pad: int, substeps: int, num_pickers: int, max_neighbours: int, barrier):
    scalar = {name: scal_ref[k] for k, name in enumerate(SCALARS)}
    h = scalar["h"]
    base = len(SCALARS) + len(COLOURS)

    def fixed():
        """What stays fixed over the control step: inverse masses, which particles are held, and their pickers' start
        and end positions and offsets. Read again in every substep rather than held across the substeps' loop: the
        program runs at its limit of 64 registers per thread, and holding these (about 20 registers) steps 2% fewer
        actions per second (``benchmarks/RESULTS.md``); the same values, so the same bits."""
        w = inv_mass_ref[...]
        holder = holder_ref[...]
        held = holder >= 0
        slot = jnp.maximum(holder, 0)
        start = [scal_ref[base + 3 * slot + a] for a in range(3)]
        end = [scal_ref[base + 3 * num_pickers + 3 * slot + a] for a in range(3)]
        offset = [offset_ref[a * n_pad:(a + 1) * n_pad] for a in range(3)]
        return w, held, start, end, offset

    def gather(ref, index, a):
        return ref[index + a * n_pad]

    def share_positions(x):
        barrier()
        for a in range(3):
            x_s[a * n_pad:(a + 1) * n_pad] = x[a]
        barrier()

    def constraints(x, w):
        def colour_pass(c, x):
            alpha = scal_ref[colours_ref[6 * c + 5]]
            rest = scal_ref[len(SCALARS) + c]
            role = roles_ref[pl.ds(c * n_pad, n_pad)]  # see colour_roles
            paired = (role & 3) != 0
            partner = jax.lax.shift_right_logical(role, 2)
            share_positions(x)
            xq = [gather(x_s, partner, a) for a in range(3)]
            wq = inv_mass_ref[partner]
            # the jax.numpy solver's pair (a, b) is (p, q) for a first particle and (q, p) for a second one; its
            # moves, a + w_a s (a - b) and b - w_b s (a - b), are both p + w_p s (p - q) to the bit (negation and
            # the sum w_a + w_b are exact either way round)
            diff = [u - v for u, v in zip(x, xq, strict=True)]
            dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
            denom = w + wq + alpha
            lam = jnp.where(paired & (denom > 0), -(dist - rest) / jnp.maximum(denom, 1e-12), 0.0)
            scale = lam / dist
            return tuple(jnp.where(paired, c + w * (scale * d), c) for c, d in zip(x, diff, strict=True))

        return list(jax.lax.fori_loop(0, len(COLOURS), colour_pass, tuple(x)))

    def tethers(x, w):
        share_positions(x)
        for k in range(num_pickers):
            to = tether_to_ref[k * n_pad:(k + 1) * n_pad]
            length = tether_len_ref[k * n_pad:(k + 1) * n_pad]
            anchor = jnp.maximum(to, 0)
            diff = [c - gather(x_s, anchor, a) for a, c in enumerate(x)]
            dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
            over = jnp.where((to >= 0) & (w > 0), jnp.maximum(dist - length, 0.0), 0.0)
            x = [c - (over / dist) * d for c, d in zip(x, diff, strict=True)]
        return x

    def separate(x, x_prev):
        distance, friction = scalar["collision_distance"], scalar["self_friction"]
        share_positions(x)

        def slot(ref, k):
            return ref[pl.ds(k * n_pad, n_pad)]

        def count(k, touching):
            nb = slot(neighbours_ref, k)
            jj = jnp.maximum(nb, 0)
            diff = [c - gather(x_s, jj, a) for a, c in enumerate(x)]
            dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
            return touching + jnp.where((nb >= 0) & (dist < distance), 1.0, 0.0)

        touching = jax.lax.fori_loop(0, max_neighbours, count, jnp.zeros((n_pad,), jnp.float32))
        # the pushes' relaxation, min(1, RELAXATION / max(crowd, 1)) with crowd the larger count of the pair, is the
        # smaller of the two particles' own reliefs (it falls as the count rises): one division per particle, not
        # one per slot
        relief = jnp.minimum(1.0, RELAXATION / jnp.maximum(touching, 1.0))
        touch_s[...] = relief
        barrier()
        moved = [c - q for c, q in zip(x, x_prev, strict=True)]

        def push(k):
            nb = slot(neighbours_ref, k)
            jj = jnp.maximum(nb, 0)
            xj = [gather(x_s, jj, a) for a in range(3)]
            diff = [c - u for c, u in zip(x, xj, strict=True)]
            dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
            inv = 1.0 / dist  # one reciprocal for the three divisions (the same bits on the GPU: see the top)
            normal = [d * inv for d in diff]
            depth = jnp.where((nb >= 0) & (dist < distance), distance - dist, 0.0)
            motion = [m - (u - gather(prev_s, jj, a)) for a, (m, u) in enumerate(zip(moved, xj, strict=True))]
            along = collision.dot_list(motion, normal)
            tangential = [m - along * nn for m, nn in zip(motion, normal, strict=True)]
            slide = jnp.sqrt(collision.dot_list(tangential, tangential) + 1e-12)
            grip = jnp.where(depth > 0, jnp.minimum(1.0, friction * depth / slide), 0.0)
            s = slot(share_ref, k) * jnp.minimum(relief, touch_s[jj])
            return [(s * depth) * nn - (s * grip) * t for nn, t in zip(normal, tangential, strict=True)]

        # the first slot's push, then the others added in order, as collision.separate
        total = jax.lax.fori_loop(1, max_neighbours, lambda k, total: tuple(
            t + u for t, u in zip(total, push(k), strict=True)), tuple(push(0)))
        return [c + t for c, t in zip(x, total, strict=True)]

    def floor(x, x_prev, w):
        depth = jnp.maximum(scalar["particle_radius"] - x[2], 0.0) * w
        tangential = [c - q for c, q in zip(x[:2], x_prev[:2], strict=True)]
        speed = jnp.sqrt(collision.dot_list(tangential, tangential))
        scale = jnp.clip(1.0 - scalar["friction"] * depth / jnp.maximum(speed, 1e-12), 0.0, 1.0)
        xy = [jnp.where(depth > 0, q + t * scale, c) for c, q, t in zip(x[:2], x_prev[:2], tangential, strict=True)]
        return [*xy, x[2] + depth]

    def substep(k, xv):
        x, v = list(xv[:3]), list(xv[3:])
        w, held, start, end, offset = fixed()
        frac = (k + 1.0) / substeps
        x_prev = x
        barrier()
        for a in range(3):
            prev_s[a * n_pad:(a + 1) * n_pad] = x_prev[a]
        v = [c * scalar["decay"] for c in v]
        v[2] = v[2] + scalar["fall"]
        x = [c + u * h for c, u in zip(x, v, strict=True)]
        x = [jnp.where(held, (s + frac * (e - s)) + o, c) for c, s, e, o in zip(x, start, end, offset, strict=True)]
        x = constraints(x, w)
        x = tethers(x, w)
        x = separate(x, x_prev)
        x = floor(x, x_prev, w)
        v = [(c - q) / h for c, q in zip(x, x_prev, strict=True)]
        return (*x, *v)

    xv = tuple(xv_ref[a * n_pad:(a + 1) * n_pad] for a in range(6))
    xv = jax.lax.fori_loop(0, substeps, substep, xv)
    for a in range(6):
        out_ref[a * n_pad:(a + 1) * n_pad] = xv[a]


def _no_barrier():
    pass


CELL_MARGIN = 1.001
"""The list skips a neighbour cell whose box lies farther than ``sqrt(CELL_MARGIN)`` x the radius from a particle;
the margin covers the rounding of ``floor(x / radius)`` (float32 positions: ~1e-7 of a metre), so no candidate within
the radius is skipped."""


LIST_BLOCK = 64
"""Particles per program of the neighbour search's walk (:func:`_walk_kernel`): the particles are dealt to programs
busiest first, so that a program walks as often as its own busiest particle has candidates, not the cloth's."""


def _cells_of(offsets_ref, radius, cell, x, inside, buckets, count_at):
    """For each of the 27 cells around each particle, in the order read, yields ``(block, bucket, within, count)``:
    the cell's coordinates and hash bucket; whether its box lies within the radius of the particle, with a margin
    over the rounding of the cells (a cell farther holds no pair of it); and ``count_at(bucket, within)``, the
    particles in the bucket (0 where not within). Unrolled: 27 copies in a kernel."""
    r2 = radius * radius
    for o in range(27):
        offset = [offsets_ref[3 * o + a] for a in range(3)]
        block = [c + d for c, d in zip(cell, offset, strict=True)]
        bucket = collision.cell_hash(block, buckets)
        gap = [jnp.where(d > 0, (c + 1).astype(jnp.float32) * radius - u,
                         jnp.where(d < 0, u - c.astype(jnp.float32) * radius, 0.0))
               for c, d, u in zip(cell, offset, x, strict=True)]
        gap = [jnp.maximum(g, 0.0) for g in gap]
        within = inside & (collision.dot_list(gap, gap) < r2 * CELL_MARGIN)
        yield block, bucket, within, count_at(bucket, within)


def _walk(tables, refs, column, i, j, x, total, r2, n, n_pad, cols, visit, carry):
    """``visit(carry, q, d2, valid)`` for every candidate ``q`` of the 27 cells of the particles at grid ``(i, j)``,
    in the order read.

    ``tables``: ``(first, end, key)`` refs, each particle's nonempty cells as runs of the sorted order (row r:
    its r-th run, in the particle's ``column``); ``refs``: ``(order, sorted_cell, xs)``. Each lane walks one
    candidate per iteration, so the loop runs as often as the lanes' busiest particle has candidates."""
    first_s, end_s, key_s = tables
    order_ref, sorted_cell_ref, xs_ref = refs
    zeros = jnp.zeros(column.shape, jnp.int32)

    def candidate(t, state):
        run, first, end, key, carry = state
        active = t < total
        later = active & (t >= end)  # the run is read: the next one
        run = run + later.astype(jnp.int32)
        row = jnp.minimum(run, 26) * n_pad + column
        # only the lanes moving to their next run read it (masked loads: the others issue no read)
        first = plgpu.load(first_s.at[row], mask=later, other=first)
        end = plgpu.load(end_s.at[row], mask=later, other=end)
        key = plgpu.load(key_s.at[row], mask=later, other=key)
        place = jnp.clip(first + t, 0, n - 1)
        # a particle done with its candidates reads nothing more
        q = plgpu.load(order_ref.at[place], mask=active, other=0)
        # q lies in the cell queried (not a hash collision)
        same = active & (plgpu.load(sorted_cell_ref.at[place], mask=active, other=0) == key)
        qi = jax.lax.div(q, jnp.int32(cols))  # q >= 0
        adjacent = (jnp.abs(qi - i) <= 1) & (jnp.abs(q - qi * cols - j) <= 1)
        near = same & ~adjacent
        # the candidate's position in the sorted copy, read beside its index rather than after it (one
        # dependent read fewer per iteration; the same values)
        d = [plgpu.load(xs_ref.at[place + a * n_pad], mask=active, other=0.0) - x[a] for a in range(3)]
        d2 = collision.dot_list(d, d)
        return run, first, end, key, visit(carry, q, d2, near & (d2 < r2))

    state = (zeros, plgpu.load(first_s.at[column]), plgpu.load(end_s.at[column]),
             plgpu.load(key_s.at[column]), carry)
    return jax.lax.fori_loop(0, jnp.max(total), candidate, state)[-1]


def _from_kept(found_s, d2_s, column, found, n_pad, visit, carry):
    """``visit(carry, q, d2, valid)`` for the candidates within the radius the walk kept, in the order read."""
    def one(k, carry):
        listed = k < found
        return visit(carry, plgpu.load(found_s.at[k * n_pad + column], mask=listed, other=0),
                     plgpu.load(d2_s.at[k * n_pad + column], mask=listed, other=0.0), listed)
    return jax.lax.fori_loop(0, jnp.max(found), one, carry)


def _walk_kernel(radius_ref, offsets_ref, deal_ref, x_ref, xs_ref, cell_ref, order_ref, sorted_cell_ref, start_ref,
                 count_ref, first_s, end_s, key_s, total_ref, found_ref, found_s, d2_s, reach_ref, *,
                 mesh: ClothMesh, n_pad: int, block: int, buckets: int, max_neighbours: int, slots: int, barrier):
    """The walk of :func:`neighbour_list` for ``block`` particles of one cloth (those the program's place in
    ``deal_ref`` names): their runs, the candidates within the radius (at most ``slots`` kept per particle), their
    counts within each reach and so their reach. Writes each particle's column ``p`` of the tables."""
    cols, n = mesh.cols, mesh.num_particles
    here = pl.program_id(0) * block + jax.lax.broadcasted_iota(jnp.int32, (block,), 0)  # columns of the tables
    p = deal_ref[here]
    i, j = p // cols, p % cols
    inside = p < n
    radius = radius_ref[0]
    r2 = radius * radius
    x = [x_ref[p + a * n_pad] for a in range(3)]
    cell = [cell_ref[p + a * n_pad] for a in range(3)]  # the cells the particles were sorted by
    zeros = jnp.zeros((block,), jnp.int32)
    runs, total = zeros, zeros
    # the nonempty cells, in the order read, as runs of the sorted order: run r's candidate t (t counts every
    # run's candidates end to end) is at place first + t, while t < end
    for block_cell, bucket, _, count in _cells_of(offsets_ref, radius, cell, x, inside, buckets, lambda b, w: (
            plgpu.load(count_ref.at[b], mask=w, other=0))):
        row = jnp.minimum(runs, 26) * n_pad + here
        first = plgpu.load(start_ref.at[bucket], mask=count > 0, other=0)  # an empty cell's is not read
        plgpu.store(first_s.at[row], first - total, mask=count > 0)
        plgpu.store(end_s.at[row], total + count, mask=count > 0)
        plgpu.store(key_s.at[row], collision.cell_key(block_cell), mask=count > 0)
        runs, total = runs + (count > 0).astype(jnp.int32), total + count
    total_ref[here] = total
    barrier()

    def keep(found, q, d2, valid):
        row = jnp.minimum(found, slots - 1) * n_pad + here
        plgpu.store(found_s.at[row], q, mask=valid & (found < slots))
        plgpu.store(d2_s.at[row], d2, mask=valid & (found < slots))
        return found + valid.astype(jnp.int32)

    refs = (order_ref, sorted_cell_ref, xs_ref)
    tables = (first_s, end_s, key_s)
    found = _walk(tables, refs, here, i, j, x, total, r2, n, n_pad, cols, keep, zeros)
    found_ref[here] = found
    barrier()
    counts = tuple(zeros for _ in collision.REACH)

    def count_within(counts, q, d2, valid):
        return tuple(c + (valid & (d2 < r2 * f)).astype(jnp.int32) for c, f in zip(counts, collision.REACH,
                                                                                   strict=True))

    counts = jax.lax.cond(jnp.max(found) <= slots,
                          lambda: _from_kept(found_s, d2_s, here, found, n_pad, count_within, counts),
                          lambda: _walk(tables, refs, here, i, j, x, total, r2, n, n_pad, cols, count_within, counts))
    reach_ref[p] = collision.reach_of(list(counts), r2, max_neighbours)


def _list_kernel(radius_ref, deal_ref, x_ref, xs_ref, order_ref, sorted_cell_ref, first_s, end_s, key_s, total_ref,
                 found_ref, found_s, d2_s, reach_ref, out_ref, overflow_ref, *,
                 mesh: ClothMesh, n_pad: int, max_neighbours: int, slots: int, barrier):
    """The listing of :func:`neighbour_list` for one cloth, from the walk's tables: the pairs under both
    particles' reach, in the order read (the candidates kept; a particle that had more walks again)."""
    rows, cols = mesh.rows, mesh.cols
    n, m = rows * cols, max_neighbours
    here = jax.lax.broadcasted_iota(jnp.int32, (n_pad,), 0)  # columns of the walk's tables
    p = deal_ref[...]
    i, j = p // cols, p % cols
    radius = radius_ref[0]
    r2 = radius * radius
    reach = reach_ref[p]
    found = found_ref[...]
    for k in range(m):
        out_ref[k * n_pad:(k + 1) * n_pad] = jnp.full((n_pad,), -1, jnp.int32)
    barrier()

    def write(listed_count, q, d2, valid):
        listed = valid & (d2 < jnp.minimum(reach, reach_ref[jnp.clip(q, 0, n - 1)]))
        plgpu.store(out_ref.at[jnp.minimum(listed_count, m - 1) * n_pad + p], q, mask=listed & (listed_count < m))
        return listed_count + listed.astype(jnp.int32)

    zeros = jnp.zeros((n_pad,), jnp.int32)

    def walk_again():
        x = [x_ref[p + a * n_pad] for a in range(3)]
        return _walk((first_s, end_s, key_s), (order_ref, sorted_cell_ref, xs_ref), here, i, j, x, total_ref[...],
                     r2, n, n_pad, cols, write, zeros)

    listed_count = jax.lax.cond(jnp.max(found) <= slots,
                                lambda: _from_kept(found_s, d2_s, here, found, n_pad, write, zeros), walk_again)
    overflow = jnp.maximum(listed_count - m, 0)
    overflow_ref[...] = overflow

    def drop_one_sided():
        p = here
        # where a particle's slots ran out, a pair may be listed by one of its particles only: unlist it
        barrier()
        keep = []
        for k in range(m):
            q = out_ref[k * n_pad + p]
            back = jnp.zeros((n_pad,), jnp.bool_)
            for k2 in range(m):
                back = back | (out_ref[k2 * n_pad + jnp.maximum(q, 0)] == p)
            keep.append(back)
        barrier()
        for k in range(m):
            row = out_ref[k * n_pad:(k + 1) * n_pad]
            out_ref[k * n_pad:(k + 1) * n_pad] = jnp.where(keep[k], row, -1)

    jax.lax.cond(jnp.max(overflow) > 0, drop_one_sided, lambda: None)


def candidate_counts(cell: jax.Array, x: jax.Array, radius: jax.Array, count: jax.Array) -> jax.Array:
    """int32 (N,): the candidates each particle walks in :func:`neighbour_list` (the particles of its 27 cells
    but those wholly beyond the radius), in jax.numpy: the walk's programs are dealt particles busiest first."""
    offsets = jnp.asarray(collision.OFFSETS.ravel())
    inside = jnp.ones(x.shape[:1], bool)
    total = jnp.zeros(x.shape[:1], jnp.int32)
    for *_, c in _cells_of(offsets, radius, collision.components(cell), collision.components(x), inside,
                           count.shape[0], lambda b, w: jnp.where(w, count[b], 0)):
        total = total + c
    return total


@functools.cache
def _list_calls(mesh: ClothMesh, max_neighbours: int, slots: int, interpret: bool, num_warps: int | None):
    n_pad = padded_size(mesh.num_particles)
    block = min(LIST_BLOCK, n_pad)
    barrier, extra = _backend(interpret, num_warps, n_pad)
    _, walk_extra = _backend(interpret, max(1, block // 64), block)  # two particles per thread
    i32, f32 = jnp.int32, jnp.float32
    walk = pl.pallas_call(
        functools.partial(_walk_kernel, mesh=mesh, n_pad=n_pad, block=block, buckets=collision.num_buckets(
            mesh.num_particles), max_neighbours=max_neighbours, slots=slots, barrier=barrier),
        out_shape=tuple(jax.ShapeDtypeStruct((rows * n_pad,), dtype) for rows, dtype in [
            (27, i32), (27, i32), (27, i32), (1, i32), (1, i32), (slots, i32), (slots, f32), (1, f32)]),
        grid=(n_pad // block,), **walk_extra)
    listing = pl.pallas_call(
        functools.partial(_list_kernel, mesh=mesh, n_pad=n_pad, max_neighbours=max_neighbours, slots=slots,
                          barrier=barrier),
        out_shape=(jax.ShapeDtypeStruct((max_neighbours * n_pad,), i32), jax.ShapeDtypeStruct((n_pad,), i32)),
        **extra)
    return walk, listing


def neighbour_rows(mesh: ClothMesh, x: jax.Array, radius: jax.Array, *, max_neighbours: int = 16, slots: int = 64,
                   interpret: bool | None = None, num_warps: int | None = None) -> tuple[jax.Array, jax.Array]:
    """:func:`.collision.neighbour_list` of one cloth's positions ``x`` (N, 3), grid neighbours excluded, as two
    kernels: the same pairs in the same order wherever the jax.numpy list's ``candidates`` slots suffice (these
    read every candidate).

    The walk (:func:`_walk_kernel`): programs of :data:`LIST_BLOCK` particles, dealt busiest first (by
    :func:`candidate_counts`), each walk the candidates of its particles' 27 cells (but cells wholly beyond the
    radius), one candidate per iteration, keep those within the radius with their squared distances, and count
    them within each reach of :data:`.collision.REACH`. The listing (:func:`_list_kernel`, one program per
    cloth): the pairs under both particles' reach. ``slots``: the candidates within ``radius`` a particle keeps
    from its walk for the listing (if one has more, its programs walk again: slower, same result). The scratch
    arrays take (max_neighbours + 2 x slots + 85) x 4 bytes per padded particle. ``num_warps``: of the listing (default
    :func:`default_warps`; the walk's programs take one warp per 64 particles). Returns int32
    ``(max_neighbours x padded_size(N),)``, the list as the substeps kernel reads it (row ``k``: each particle's
    ``k``-th pair, -1 for none and for the padding), and the int32 overflow (listed pairs past a particle's slots)."""
    n, n_pad = mesh.num_particles, padded_size(mesh.num_particles)
    if interpret is None:
        interpret = jax.default_backend() != "gpu"
    radius = jnp.asarray(radius, jnp.float32)
    cell, order, start, count = collision.sorted_cells(x, radius)
    # the busiest first, the padding last (a stable sort: the same deal every time)
    busy = jnp.pad(candidate_counts(cell, x, radius, count), (0, n_pad - n), constant_values=-1)
    deal = jnp.argsort(-busy, stable=True).astype(jnp.int32)

    def rows(a):
        return jnp.concatenate([jnp.pad(a[:, c], (0, n_pad - n)) for c in range(a.shape[1])])

    walk, listing = _list_calls(mesh, int(max_neighbours), int(slots), bool(interpret), num_warps)
    radius_row = jnp.pad(radius[None], (0, 15))
    x_rows, xs_rows = rows(x), rows(x[order])
    sorted_order = jnp.pad(order, (0, n_pad - n))
    sorted_key = jnp.pad(collision.cell_key(collision.components(cell))[order], (0, n_pad - n))
    tables = walk(radius_row, jnp.asarray(np.pad(collision.OFFSETS.ravel(), (0, 128 - 81))), deal, x_rows, xs_rows,
                  rows(cell), sorted_order, sorted_key, start, count)
    out, overflow = listing(radius_row, deal, x_rows, xs_rows, sorted_order, sorted_key, *tables)
    return out, jnp.sum(overflow)


def neighbour_list(mesh: ClothMesh, x: jax.Array, radius: jax.Array, *, max_neighbours: int = 16,
                   **kwargs) -> tuple[jax.Array, jax.Array]:
    """:func:`neighbour_rows` as :func:`.collision.neighbour_list` gives it: int32 (N, max_neighbours) and the
    overflow (keywords as :func:`neighbour_rows`)."""
    rows, overflow = neighbour_rows(mesh, x, radius, max_neighbours=max_neighbours, **kwargs)
    return rows.reshape(max_neighbours, -1)[:, :mesh.num_particles].T, overflow


def _backend(interpret: bool, num_warps: int | None, n_pad: int):
    """``(barrier, pallas_call keywords)`` for the interpreter or the GPU; ``num_warps`` None: :func:`default_warps`."""
    if interpret:
        return _no_barrier, {"interpret": True}
    num_warps = default_warps(n_pad) if num_warps is None else int(num_warps)
    return plgpu.debug_barrier, {"compiler_params": plgpu.CompilerParams(num_warps=num_warps, num_stages=1)}


@functools.cache
def _call(mesh: ClothMesh, substeps: int, num_pickers: int, max_neighbours: int, interpret: bool,
          num_warps: int | None):
    n_pad = padded_size(mesh.num_particles)
    barrier, extra = _backend(interpret, num_warps, n_pad)
    kernel = functools.partial(_kernel, mesh=mesh, n_pad=n_pad, substeps=int(substeps), num_pickers=num_pickers,
                               max_neighbours=max_neighbours, barrier=barrier)
    f32 = jnp.float32
    return pl.pallas_call(kernel, out_shape=(jax.ShapeDtypeStruct((6 * n_pad,), f32),
                                             jax.ShapeDtypeStruct((3 * n_pad,), f32),
                                             jax.ShapeDtypeStruct((3 * n_pad,), f32),
                                             jax.ShapeDtypeStruct((n_pad,), f32)), **extra)


def run_substeps(mesh: ClothMesh, substeps: int, x, v, inv_mass, holder, offset, start, end, tether_to,
                 tether_length, neighbours, scalars, *, interpret: bool | None = None,
                 num_warps: int | None = None):
    """The substeps of one control step of one cloth (see :meth:`.physics.ClothPhysics.step`), fused.

    Args:
      mesh: the particle grid (N particles).
      substeps: how many substeps to run.
      x: positions, three float32 (N,) arrays (metres).
      v: velocities, three float32 (N,) arrays (m/s).
      inv_mass: float32 (N,), 0 for held particles.
      holder: int32 (N,), the picker holding each particle (-1: none).
      offset: three float32 (N,) arrays, held particle minus picker.
      start: float32 (K, 3), the pickers' positions at the step's start.
      end: float32 (K, 3), the pickers' positions at the step's end.
      tether_to: int32 (N, K) (-1: none).
      tether_length: float32 (N, K), metres.
      neighbours: int32 (M x padded_size(N),) from :func:`neighbour_rows` (row ``k``: each particle's ``k``-th
        pair, -1: none). Each pair's share of its push (:func:`.collision.pair_shares`) is computed here.
      scalars: float32 (len(SCALARS),) in the order of :data:`SCALARS`.
      interpret: run in Pallas' interpreter (default: on any backend but a GPU).
      num_warps: per program (default :func:`default_warps`).

    Returns:
      positions and velocities, three float32 (N,) arrays each.
    """
    n, n_pad = mesh.num_particles, padded_size(mesh.num_particles)
    k, m = start.shape[0], neighbours.shape[0] // n_pad
    if interpret is None:
        interpret = jax.default_backend() != "gpu"

    def pad(a, value=0):
        return jnp.pad(a, (0, n_pad - n), constant_values=value)

    def rows(a, value=0):
        return jnp.concatenate([pad(a[:, c], value) for c in range(a.shape[1])])

    rests = np.hypot(COLOURS[:, 0], COLOURS[:, 1]) * mesh.spacing  # metres, as .physics._constraint_pairs
    scal = jnp.concatenate([jnp.asarray(scalars, jnp.float32), jnp.asarray(rests, jnp.float32), start.ravel(),
                            end.ravel()])
    scal = jnp.pad(scal, (0, padded_size(scal.shape[0]) - scal.shape[0]))
    xv = jnp.concatenate([pad(c) for c in (*x, *v)])
    colours = jnp.asarray(np.pad(COLOURS.ravel(), (0, padded_size(COLOURS.size) - COLOURS.size)))
    w = pad(inv_mass)
    share = collision.pair_share(w, w[jnp.maximum(neighbours, 0).reshape(m, n_pad)]).ravel()  # as the list
    out = _call(mesh, int(substeps), int(k), int(m), bool(interpret), num_warps)(
        scal, colours, jnp.asarray(colour_roles(mesh)), xv, w, pad(holder, -1),
        jnp.concatenate([pad(c) for c in offset]),
        rows(tether_to, -1), rows(tether_length), neighbours, share)[0]
    parts = tuple(out[a * n_pad:a * n_pad + n] for a in range(6))
    return parts[:3], parts[3:]
