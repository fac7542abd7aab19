"""Self-collision of a particle cloth: a neighbour list from a hashed uniform grid, and its resolution.

Finding close particle pairs by testing all N^2 pairs costs 2.6 million tests per substep for a 40 x 40
cloth. Instead, once per control step, :func:`neighbour_list` hashes particles into cubic cells of side
``radius`` (the search radius: the collision distance plus a margin for the motion within the step), and
each particle tests the particles of the 3 x 3 x 3 cells around its own, at most ``candidates`` of them,
keeping its ``max_neighbours`` nearest non-adjacent particles within ``radius`` (mutual pairs only). Each
substep, :func:`separate` pushes apart the listed pairs closer than the collision distance.

Limits (documented, deliberate, and counted: ``overflow``): a particle reads at most ``candidates``
particles and keeps at most ``max_neighbours``; both only bind in piles many layers deep.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

_PRIMES = (73856093, 19349663, 83492791)

RELAXATION = 1.5
"""Over-relaxation of the averaged self-collision correction (Macklin et al. 2014 suggest 1 to 2)."""

Vec = tuple[jax.Array, ...]
"""A vector field over the particles as its per-coordinate (N,) arrays (see :func:`components`)."""


REACH = (1.0, 0.75, 0.5, 0.35, 0.25)
"""Fractions of the squared search radius a particle's reach may take (see :func:`neighbour_list`)."""


def reach_of(counts: list[jax.Array], r2: jax.Array, max_neighbours: int) -> jax.Array:
    """float32 (N,): each particle's squared reach, ``r2`` times the largest of :data:`REACH` whose count of
    particles within (``counts``, one (N,) int array per entry of :data:`REACH`) is at most ``max_neighbours``,
    else the smallest."""
    reach = r2 * REACH[-1] + jnp.zeros(counts[0].shape, jnp.float32)
    for f, count in reversed(list(zip(REACH, counts, strict=True))):
        reach = jnp.where(count <= max_neighbours, r2 * f, reach)
    return reach


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """Sum over the last axis of ``a * b`` as explicit adds in a fixed order.

    XLA's reductions may add in a different order for different batch sizes; a cloth amplifies such
    last-bit differences, so every sum in the physics is written out, which keeps an episode the same in
    any batch.
    """
    total = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        total = total + a[..., i] * b[..., i]
    return total


def dot_list(a: list[jax.Array], b: list[jax.Array]) -> jax.Array:
    """:func:`dot` of vectors given as lists of their components."""
    total = a[0] * b[0]
    for u, v in zip(a[1:], b[1:], strict=True):
        total = total + u * v
    return total


def fixed_sum(x: jax.Array, axis: int) -> jax.Array:
    """Sum along ``axis`` as a pairwise tree of explicit adds (see :func:`dot`)."""
    x = jnp.moveaxis(x, axis, 0)
    while x.shape[0] > 1:
        if x.shape[0] % 2:
            x = jnp.concatenate([x, jnp.zeros_like(x[:1])])
        x = x[0::2] + x[1::2]
    return x[0]


def fixed_matmul(a: jax.Array, b: jax.Array) -> jax.Array:
    """``a @ b`` for a small inner size, (..., n, k) @ (k, m), as explicit adds in a fixed order (see :func:`dot`).

    A batched matmul's summation order can change with the batch size; this one's does not.
    """
    total = a[..., :, 0, None] * b[0]
    for i in range(1, a.shape[-1]):
        total = total + a[..., :, i, None] * b[i]
    return total


def cell_hash(cell: Vec, buckets: int) -> jax.Array:
    """int32 bucket in ``[0, buckets)`` of integer cell coordinates given as three int32 arrays (buckets a power
    of 2). Plain integer arithmetic, so the jax.numpy list and the kernels of :mod:`.fused` share it."""
    c = [v.astype(jnp.uint32) for v in cell]
    h = c[0] * jnp.uint32(_PRIMES[0])
    h = h ^ (c[1] * jnp.uint32(_PRIMES[1])) ^ (c[2] * jnp.uint32(_PRIMES[2]))
    return (h & jnp.uint32(buckets - 1)).astype(jnp.int32)


def cell_key(cell: Vec) -> jax.Array:
    """int32 of integer cell coordinates (three int32 arrays), 10 bits each: equal for cells 1024 apart along
    an axis (over 10 m for any cloth here), whose particles the distance test then rejects."""
    c = [v & 1023 for v in cell]
    return c[0] | (c[1] << 10) | (c[2] << 20)


def components(x: jax.Array) -> tuple[jax.Array, ...]:
    """The last-axis entries of ``x`` (..., 3) as three (...) arrays: gathers and sums over them run several
    times faster on a GPU than over a trailing axis of 3 (same arithmetic, same results)."""
    return tuple(x[..., a] for a in range(x.shape[-1]))


OFFSETS = np.stack(np.meshgrid(*([np.arange(-1, 2, dtype=np.int32)] * 3), indexing="ij"), -1).reshape(27, 3)
"""The 3 x 3 x 3 cells around a cell, in the order a particle reads them."""


def num_buckets(n: int) -> int:
    """Hash buckets for ``n`` particles: a power of 2, at least 2 n."""
    return 1 << max(4, (2 * n - 1).bit_length())


def sorted_cells(x: jax.Array, radius: jax.Array):
    """Particles sorted by the hashed cubic cell of side ``radius`` they lie in.

    Returns:
      cell: int32 (N, 3) cell coordinates; order: int32 (N,) particles by bucket (stable); start: int32
      (buckets,) first place of each bucket in ``order`` (N if empty); count: int32 (buckets,) particles in it.
    """
    n = x.shape[0]
    buckets = num_buckets(n)
    cell = jnp.floor(x / radius).astype(jnp.int32)
    key = cell_hash(components(cell), buckets)
    order = jnp.argsort(key).astype(jnp.int32)
    start = jnp.full((buckets,), n, jnp.int32).at[key[order]].min(jnp.arange(n, dtype=jnp.int32))
    count = jnp.zeros((buckets,), jnp.int32).at[key].add(1)
    return cell, order, start, count


def neighbour_list(x: jax.Array, radius: jax.Array, excluded, *, candidates: int = 192,
                   max_neighbours: int = 16) -> tuple[jax.Array, jax.Array]:
    """The close pairs of each particle: other particles within ``radius``, at most ``max_neighbours``.

    Particles are hashed into cubic cells of side ``radius`` and sorted by cell; each particle reads the
    particles of the 3 x 3 x 3 cells around its own (any particle within ``radius`` lies in them), the
    cells' ranges of the sorted order laid end to end into ``candidates`` slots. A pair is listed if its
    distance is under both particles' reach, and each particle lists its pairs in the order read. A
    particle's reach is ``radius`` times the largest of :data:`REACH` with at most ``max_neighbours``
    particles within it (the smallest if none: the pairs past its slots are then counted in ``overflow``).
    Where at most ``max_neighbours`` particles lie within ``radius`` (any cloth but a deep pile) the list
    holds every pair within ``radius``; in a pile it keeps the nearest ones. Every pair is listed by both
    of its particles or by neither: a pair listed by one only would push one and not the other, a net force
    that makes a resting pile crawl.

    Args:
      x: float32 (N, 3) positions, metres.
      radius: search radius, metres (a traced scalar is fine).
      excluded: ``(i (N, M), j (N, M)) -> bool (N, M)``, pairs never listed (grid neighbours); ``i == j``
        is excluded always.
      candidates: particles read per particle (static). A 40 x 40 cloth crumpled into a pile has up to about
        170 particles in a particle's 27 cells.
      max_neighbours: entries kept per particle (static).

    Returns:
      int32 (N, max_neighbours) neighbour indices (-1: none; every pair listed by both its particles), and
      int32 scalar ``overflow``: particles the candidate slots could not hold plus pairs past a particle's
      list, summed over particles (0 unless the cloth is piled deep; missed pairs go unchecked, so this is
      reported).
    """
    n = x.shape[0]
    cell, order, start, count = sorted_cells(x, radius)
    buckets = start.shape[0]
    offsets = jnp.asarray(OFFSETS)
    block = cell[:, None, :] + offsets[None]  # (N, 27, 3)
    bucket = cell_hash(components(block), buckets)  # (N, 27)
    # the 27 buckets' ranges of the sorted order, end to end: slot k reads bucket c(k) at k - before[c(k)]
    sizes = count[bucket]
    ends = jnp.cumsum(sizes, axis=1)  # (N, 27)
    slot = jnp.arange(candidates, dtype=jnp.int32)
    which = jnp.sum(ends[:, None, :] <= slot[None, :, None], axis=-1)  # (N, C): c(k), 27 past the end
    filled = which < 27
    which = jnp.minimum(which, 26)
    first = jnp.take_along_axis(start[bucket] - (ends - sizes), which, axis=1)
    index = jnp.minimum(first + slot[None], n - 1)  # into the sorted order: 27 runs of neighbouring slots
    candidate = order[index]
    # a bucket may hold other cells (hash collisions), and two of the 27 cells may share a bucket: keep a
    # particle only where it really lies in the cell queried, which also lists every particle once. What is
    # read of each candidate is read from copies in the sorted order at ``index`` (runs of neighbouring
    # memory) rather than at ``candidate`` (scattered): the same values, the whole list 14% faster for 1024
    # cloths on an H100
    queried = jnp.take_along_axis(cell_key(components(block)), which, axis=1)
    valid = filled & (cell_key(components(cell))[order][index] == queried)
    me = jnp.arange(n, dtype=jnp.int32)[:, None]
    valid &= (candidate != me) & ~excluded(jnp.broadcast_to(me, candidate.shape), candidate)
    d2 = None
    for c in components(x):
        d = c[order][index] - c[:, None]
        d2 = d * d if d2 is None else d2 + d * d
    return _list_within_reach(valid, d2, radius * radius, slot[None], candidate, lambda reach: reach[order][index],
                              jnp.sum(jnp.maximum(ends[:, -1] - candidates, 0)), max_neighbours)


def _list_within_reach(valid, d2, r2, slot, candidate, reach_of_candidate, unread, max_neighbours):
    """The end of both searches: of the candidates read (``valid``, squared distances ``d2``, both (N, C); ``slot``:
    the order read, broadcasting to them; ``candidate``: their particles), the first ``max_neighbours`` in the order
    read closer than both particles' reach (``reach_of_candidate(reach)``: the candidates' reach, (N, C)), unlisted
    where one particle only lists them. Returns them and the overflow: ``unread`` (candidates past the slots) plus
    the listed pairs past ``max_neighbours``."""
    valid &= d2 < r2
    reach = reach_of([jnp.sum(valid & (d2 < r2 * f), axis=1) for f in REACH], r2, max_neighbours)
    listed = valid & (d2 < jnp.minimum(reach[:, None], reach_of_candidate(reach)))
    order_read = jnp.where(listed, -slot.astype(jnp.float32), -jnp.inf)  # the first listed, in order read
    best, pick = jax.lax.top_k(order_read, max_neighbours)
    chosen = jnp.where(jnp.isfinite(best), jnp.take_along_axis(candidate, pick, axis=1), -1)
    chosen = mutual(chosen)  # where slots ran out (overflow), a pair may be listed by one particle only
    overflow = unread + jnp.sum(jnp.maximum(jnp.sum(listed, axis=1) - max_neighbours, 0))
    return chosen, overflow


def neighbour_list_pairwise(x: jax.Array, radius: jax.Array, excluded, *, candidates: int = 192,
                            max_neighbours: int = 16) -> tuple[jax.Array, jax.Array]:
    """:func:`neighbour_list`'s result (the same pairs in the same order, the same ``overflow``), found by testing
    every particle pair instead of reading ``candidates`` slots per particle: cheaper for small cloths on a CPU
    (N^2 pairs against N x ``candidates`` slots and their 27 cell ranges; 10 x 10 cloths: 4x faster, 16 x 16:
    1.6x, 24 x 24: 2x slower), where XLA's gathers cost far more than arithmetic.

    The slot :func:`neighbour_list` reads particle ``j`` in for particle ``i`` is computed instead of read: ``j``
    is read in the one of ``i``'s 27 cells whose key equals its own (at most one: keys agree to 10 bits per
    axis), at that cell's first slot plus ``j``'s place in its bucket's run of the sorted order. Pairs beyond
    ``candidates`` slots are dropped, the first ``max_neighbours`` listed ones kept in slot order, as there.
    Needs ``max_neighbours <= min(N, candidates)``.
    """
    n = x.shape[0]
    cell, order, start, count = sorted_cells(x, radius)
    buckets = start.shape[0]
    block = cell[:, None, :] + jnp.asarray(OFFSETS)[None]  # (N, 27, 3)
    sizes = count[cell_hash(components(block), buckets)]  # (N, 27)
    ends = jnp.cumsum(sizes, axis=1)
    me = jnp.arange(n, dtype=jnp.int32)
    # each particle's place in its bucket's run of the sorted order
    within = jnp.zeros((n,), jnp.int32).at[order].set(me) - start[cell_hash(components(cell), buckets)]
    # (i, j): which of i's 27 cells (OFFSETS' order) has j's key, if any
    step = [(cj[None, :] - ci[:, None] + 1) & 1023 for ci, cj in zip(components(cell), components(cell),
                                                                     strict=True)]
    read = (step[0] <= 2) & (step[1] <= 2) & (step[2] <= 2)
    which = jnp.minimum(step[0] * 9 + step[1] * 3 + step[2], 26)
    slot = (ends - sizes).reshape(-1)[me[:, None] * 27 + which] + within[None, :]  # (N, N)
    i, j = jnp.broadcast_to(me[:, None], (n, n)), jnp.broadcast_to(me[None, :], (n, n))
    valid = read & (slot < candidates) & (j != i) & ~excluded(i, j)
    d2 = None
    for c in components(x):  # as neighbour_list: candidate minus particle, the components' squares in order
        d = c[None, :] - c[:, None]
        d2 = d * d if d2 is None else d2 + d * d
    return _list_within_reach(valid, d2, radius * radius, slot, j, lambda reach: reach[None, :],
                              jnp.sum(jnp.maximum(ends[:, -1] - candidates, 0)), max_neighbours)


def mutual(neighbours: jax.Array) -> jax.Array:
    """``neighbours`` (N, M) without the pairs that only one of their particles lists (set to -1)."""
    me = jnp.arange(neighbours.shape[0], dtype=jnp.int32)[:, None, None]
    back = jnp.take(neighbours, jnp.maximum(neighbours, 0), axis=0)  # (N, M, M): my neighbours' lists
    return jnp.where(jnp.any(back == me, axis=-1), neighbours, -1)


def pair_shares(inv_mass: jax.Array, neighbours: jax.Array) -> jax.Array:
    """float32 (N, M): the share ``w_i / (w_i + w_j)`` of each listed pair's correction that :func:`separate`
    moves particle ``i`` (``w``: ``inv_mass``; 0 if both are held fixed). Constant over a control step."""
    return pair_share(inv_mass[:, None], inv_mass[jnp.maximum(neighbours, 0)])


def pair_share(wi: jax.Array, wj: jax.Array) -> jax.Array:
    """:func:`pair_shares` of particles of inverse masses ``wi`` and ``wj`` (broadcasting float32 arrays)."""
    return jnp.where(wi + wj > 0, wi / jnp.maximum(wi + wj, 1e-12), 0.0)


def separate(x: Vec, x_prev: Vec, share: jax.Array, neighbours: jax.Array, distance: jax.Array,
             friction: jax.Array) -> Vec:
    """Pushes listed pairs closer than ``distance`` apart, with Coulomb friction between them.

    Jacobi with averaging: each pair's correction is split between its particles by inverse mass and
    scaled by ``RELAXATION / c`` (at most 1), ``c`` the larger of the two particles' counts of touching
    pairs. Summing every pair's full correction instead overshoots wherever a particle touches several
    others (a particle on a layer touches five or six), pumping energy into a resting pile; scaling
    both ends of a pair alike keeps the pushes equal and opposite, so the pile's momentum is conserved
    (Macklin et al. 2014, section 4.2, average per particle instead, which leaves a net force).
    Friction (position-based, as Macklin et al. 2014) removes the pair's relative tangential motion
    over the substep up to ``friction`` times the penetration depth. Positions are given per coordinate
    (see :func:`components`).

    Args:
      x: positions, three float32 (N,) arrays.
      x_prev: positions at the start of the substep, likewise.
      share: float32 (N, M) from :func:`pair_shares`.
      neighbours: int32 (N, M) from :func:`neighbour_list` (-1 entries ignored).
      distance: pairs closer than this are pushed apart, metres.
      friction: Coulomb friction coefficient.
    """
    j = jnp.maximum(neighbours, 0)
    diff = [c[:, None] - c[j] for c in x]
    dist = jnp.sqrt(dot_list(diff, diff) + 1e-12)
    normal = [d / dist for d in diff]
    depth = jnp.where((neighbours >= 0) & (dist < distance), distance - dist, 0.0)
    moved = [c - p for c, p in zip(x, x_prev, strict=True)]
    motion = [m[:, None] - m[j] for m in moved]
    along = dot_list(motion, normal)
    tangential = [m - along * n for m, n in zip(motion, normal, strict=True)]
    slide = jnp.sqrt(dot_list(tangential, tangential) + 1e-12)
    grip = jnp.where(depth > 0, jnp.minimum(1.0, friction * depth / slide), 0.0)
    touching = jnp.sum(depth > 0, axis=1)
    crowd = jnp.maximum(touching[:, None], touching[j]).astype(jnp.float32)
    share = share * jnp.minimum(1.0, RELAXATION / jnp.maximum(crowd, 1.0))
    out = []
    for c, n, t in zip(x, normal, tangential, strict=True):
        push = (share * depth) * n - (share * grip) * t
        total = push[:, 0]
        for k in range(1, push.shape[1]):  # explicit adds in a fixed order, as fixed_sum
            total = total + push[:, k]
        out.append(c + total)
    return tuple(out)
