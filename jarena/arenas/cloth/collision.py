"""Self-collision of a particle cloth: a neighbour list from a hashed uniform grid, and its resolution.

Finding close particle pairs by testing all N^2 pairs costs 2.6 million tests per substep for a 40 x 40
cloth. Instead, once per control step, :func:`neighbour_list` hashes particles into cubic cells of side
``2 radius`` (``radius``: the search radius, the collision distance plus a margin for the motion within the
step), and each particle tests the particles of the 2 x 2 x 2 block of cells nearest to it, at most ``slots``
per cell, keeping its ``max_neighbours`` nearest non-adjacent particles within ``radius``. Each substep,
:func:`separate` pushes apart the listed pairs closer than the collision distance.

Limits (documented, deliberate): a cell with more than ``slots`` particles lists only ``slots`` of them,
and a particle keeps only its ``max_neighbours`` nearest; both only bind in piles many layers deep.
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


def _windows(values: jax.Array, start: jax.Array, size: int) -> jax.Array:
    """``values[start + s]`` for ``s < size``, shape ``start.shape + (size,)`` (``start <= len(values)``).

    One gather of contiguous windows: on a GPU its indices are ``start.shape``, not ``size`` times larger,
    which makes it cheaper than gathering each element (entries past the end of ``values`` read 0).
    """
    padded = jnp.concatenate([values, jnp.zeros((size,), values.dtype)])
    window = jax.vmap(lambda s: jax.lax.dynamic_slice(padded, (s,), (size,)))
    return window(start.ravel()).reshape(*start.shape, size)


def neighbour_list(x: jax.Array, radius: jax.Array, excluded, *, slots: int = 16,
                   max_neighbours: int = 16) -> tuple[jax.Array, jax.Array]:
    """The nearest other particles of each particle within ``radius``, and how many the cells held back.

    Particles are hashed into cubic cells of side ``radius``; each particle tests the first ``slots``
    particles of each of the 3 x 3 x 3 cells around its own (any particle within ``radius`` lies in them)
    and keeps its ``max_neighbours`` nearest non-excluded ones within ``radius``.

    Args:
      x: float32 (N, 3) positions, metres.
      radius: search radius, metres (a traced scalar is fine).
      excluded: ``(i (N, M), j (N, M)) -> bool (N, M)``, pairs never listed (grid neighbours); ``i == j``
        is excluded always.
      slots: particles read per cell; max_neighbours: entries kept per particle (both static).

    Returns:
      int32 (N, max_neighbours) neighbour indices (-1: none; every pair listed by both its particles), and
      int32 scalar ``overflow``: the particles
      the cells held back (cells fuller than ``slots``), 0 unless the cloth is piled deeper than ``slots``
      allows. A held-back pair is missed by one side or both, so the count is reported, not hidden.
    """
    n = x.shape[0]
    buckets = 1 << max(4, (2 * n - 1).bit_length())
    scaled = x / radius
    cell = jnp.floor(scaled).astype(jnp.int32)
    key = _hash(cell, buckets)
    order = jnp.argsort(key).astype(jnp.int32)
    start = jnp.full((buckets,), n, jnp.int32).at[key[order]].min(jnp.arange(n, dtype=jnp.int32))
    count = jnp.zeros((buckets,), jnp.int32).at[key].add(1)
    offsets = jnp.stack(jnp.meshgrid(*([jnp.arange(-1, 2, dtype=jnp.int32)] * 3), indexing="ij"), -1).reshape(27, 3)
    block = cell[:, None, :] + offsets[None]  # (N, 27, 3)
    bucket = _hash(block, buckets)  # (N, 27)
    # each queried bucket's first `slots` particles in key order: windows of the arrays sorted by key
    first = start[bucket]
    filled = jnp.arange(slots, dtype=jnp.int32) < count[bucket][..., None]  # (N, 27, slots)
    candidate = _windows(order, first, slots)
    # a bucket may hold other cells (hash collisions): keep only particles really in the queried cell,
    # which also lists every particle once
    really = _windows(_pack(cell)[order], first, slots) == _pack(block)[:, :, None]
    candidate = candidate.reshape(n, -1)
    valid = (filled & really).reshape(n, -1)
    me = jnp.arange(n, dtype=jnp.int32)[:, None]
    valid &= (candidate != me) & ~excluded(jnp.broadcast_to(me, candidate.shape), candidate)
    d2 = None
    for c in components(x):
        d = _windows(c[order], first, slots).reshape(n, -1) - c[:, None]
        d2 = d * d if d2 is None else d2 + d * d
    valid &= d2 < radius * radius
    score = jnp.where(valid, -d2, -jnp.inf)
    best, pick = jax.lax.top_k(score, max_neighbours)
    chosen = jnp.where(jnp.isfinite(best), jnp.take_along_axis(candidate, pick, axis=1), -1)
    # keep mutual pairs only: a pair one particle lists and the other does not (it has max_neighbours
    # nearer ones, or a full cell hid one from the other) would push one and not the other, a net force
    back = jnp.take(chosen, jnp.maximum(chosen, 0), axis=0)  # (N, M, M): my neighbours' lists
    chosen = jnp.where(jnp.any(back == me[:, :, None], axis=-1), chosen, -1)
    overflow = jnp.sum(jnp.maximum(count - slots, 0))
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
