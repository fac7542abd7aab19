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

_PRIMES = (73856093, 19349663, 83492791)

RELAXATION = 1.5
"""Over-relaxation of the averaged self-collision correction (Macklin et al. 2014 suggest 1 to 2)."""

Vec = tuple[jax.Array, ...]
"""A vector field over the particles as its per-coordinate (N,) arrays (see :func:`components`)."""


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


def _hash(cells: jax.Array, buckets: int) -> jax.Array:
    """int32 bucket in ``[0, buckets)`` of integer cell coordinates ``(..., 3)`` (buckets a power of 2)."""
    c = cells.astype(jnp.uint32)
    h = c[..., 0] * jnp.uint32(_PRIMES[0])
    h = h ^ (c[..., 1] * jnp.uint32(_PRIMES[1])) ^ (c[..., 2] * jnp.uint32(_PRIMES[2]))
    return (h & jnp.uint32(buckets - 1)).astype(jnp.int32)


def _pack(cells: jax.Array) -> jax.Array:
    """int32 of integer cell coordinates ``(..., 3)``, 10 bits each: equal for cells 1024 apart along an axis
    (over 10 m for any cloth here), whose particles the distance test then rejects."""
    c = cells & 1023
    return c[..., 0] | (c[..., 1] << 10) | (c[..., 2] << 20)


def components(x: jax.Array) -> tuple[jax.Array, ...]:
    """The columns of ``x`` (N, 3) as three (N,) arrays: gathers and sums over them run several times faster
    on a GPU than over a trailing axis of 3 (same arithmetic, same results)."""
    return tuple(x[:, a] for a in range(x.shape[1]))


def neighbour_list(x: jax.Array, radius: jax.Array, excluded, *, candidates: int = 192,
                   max_neighbours: int = 16) -> tuple[jax.Array, jax.Array]:
    """The nearest other particles of each particle within ``radius``, and how many the search missed.

    Particles are hashed into cubic cells of side ``radius`` and sorted by cell; each particle reads the
    particles of the 3 x 3 x 3 cells around its own (any particle within ``radius`` lies in them), the
    cells' ranges of the sorted order laid end to end into ``candidates`` slots, and keeps its
    ``max_neighbours`` nearest non-excluded ones within ``radius``. Only mutual pairs are kept: a pair one
    particle lists and the other does not (it has ``max_neighbours`` nearer ones, or its slots ran out)
    would push one and not the other, a net force that makes a resting pile crawl.

    Args:
      x: float32 (N, 3) positions, metres.
      radius: search radius, metres (a traced scalar is fine).
      excluded: ``(i (N, M), j (N, M)) -> bool (N, M)``, pairs never listed (grid neighbours); ``i == j``
        is excluded always.
      candidates: particles read per particle; max_neighbours: entries kept per particle (both static).
        A 40 x 40 cloth crumpled into a pile has up to about 170 particles in a particle's 27 cells.

    Returns:
      int32 (N, max_neighbours) neighbour indices (-1: none; every pair listed by both its particles), and
      int32 scalar ``overflow``: the particles the slots could not hold, summed over particles (0 unless
      the cloth is piled deeper than ``candidates`` allows; missed pairs go unchecked, so this is reported).
    """
    n = x.shape[0]
    buckets = 1 << max(4, (2 * n - 1).bit_length())
    cell = jnp.floor(x / radius).astype(jnp.int32)
    key = _hash(cell, buckets)
    order = jnp.argsort(key).astype(jnp.int32)
    start = jnp.full((buckets,), n, jnp.int32).at[key[order]].min(jnp.arange(n, dtype=jnp.int32))
    count = jnp.zeros((buckets,), jnp.int32).at[key].add(1)
    offsets = jnp.stack(jnp.meshgrid(*([jnp.arange(-1, 2, dtype=jnp.int32)] * 3), indexing="ij"), -1).reshape(27, 3)
    block = cell[:, None, :] + offsets[None]  # (N, 27, 3)
    bucket = _hash(block, buckets)  # (N, 27)
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
    queried = jnp.take_along_axis(_pack(block), which, axis=1)
    valid = filled & (_pack(cell)[order][index] == queried)
    me = jnp.arange(n, dtype=jnp.int32)[:, None]
    valid &= (candidate != me) & ~excluded(jnp.broadcast_to(me, candidate.shape), candidate)
    d2 = None
    for c in components(x):
        d = c[order][index] - c[:, None]
        d2 = d * d if d2 is None else d2 + d * d
    valid &= d2 < radius * radius
    score = jnp.where(valid, -d2, -jnp.inf)
    best, pick = jax.lax.top_k(score, max_neighbours)
    chosen = jnp.where(jnp.isfinite(best), jnp.take_along_axis(candidate, pick, axis=1), -1)
    back = jnp.take(chosen, jnp.maximum(chosen, 0), axis=0)  # (N, M, M): my neighbours' lists
    chosen = jnp.where(jnp.any(back == me[:, :, None], axis=-1), chosen, -1)
    overflow = jnp.sum(jnp.maximum(ends[:, -1] - candidates, 0))
    return chosen, overflow


def pair_shares(inv_mass: jax.Array, neighbours: jax.Array) -> jax.Array:
    """float32 (N, M): the share ``w_i / (w_i + w_j)`` of each listed pair's correction that :func:`separate`
    moves particle ``i`` (``w``: ``inv_mass``; 0 if both are held fixed). Constant over a control step."""
    wi, wj = inv_mass[:, None], inv_mass[jnp.maximum(neighbours, 0)]
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
      x: positions, three float32 (N,) arrays; x_prev: positions at the start of the substep, likewise;
        share: float32 (N, M) from :func:`pair_shares`; neighbours: int32 (N, M) from :func:`neighbour_list`
        (-1 entries ignored); distance: metres; friction: coefficient.
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
