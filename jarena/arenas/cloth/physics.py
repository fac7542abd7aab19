"""Cloth physics: extended position-based dynamics (XPBD) on a particle grid, with pickers.

One control step of ``dt`` seconds runs ``substeps`` XPBD substeps ("small steps": one constraint
iteration per substep, which converges better than many iterations of one large step). Each substep:

1. gravity and velocity damping on the free particles, then a position prediction ``x + v h``;
2. grasped particles follow their picker (infinite mass, fixed offset);
3. distance constraints in Gauss-Seidel order by graph colouring of the grid (12 passes, each a set of
   disjoint particle pairs solved exactly in parallel): stretch (grid neighbours), shear (diagonals) and
   bending (neighbours two apart), each with an XPBD compliance (inverse stiffness, m/N);
4. long-range attachments (tethers, Kim et al. 2012): no free particle is farther from the nearest particle
   a picker holds than their distance on the flat cloth, which keeps a hanging cloth from stretching;
5. self-collision: every particle pair not adjacent on the grid is kept ``self_collision_distance`` apart
   (pairs from a neighbour list built once per control step, see :mod:`.collision`), so a folded cloth
   keeps its layers apart and a crumpled one does not pass through itself;
6. the floor: no particle below ``particle_radius``, with Coulomb friction on its tangential motion;
7. velocities from the positions' change.

Within a step, positions and velocities are kept per coordinate (three (N,) arrays, see
:func:`.collision.components`): the same arithmetic, which XLA fuses much better on a GPU than arrays with a
trailing axis of 3.

Pickers (SoftGym's): K points, each moved by a displacement per control step. A picker that closes
grasps the top layer of free particles under it: within ``grasp_radius`` of its centre in x-y and within
``grasp_depth`` of the highest of those (at most ``max_held``, nearest first), provided the picker reaches
down to that surface;
held particles keep their offset to the picker until it opens. Open pickers do not touch the cloth.

Control: float32 ``(K, 4)`` per picker ``(dx, dy, dz, grip)``: displacement in metres over the step
(within ``+-MAX_PICKER_STEP``), and ``grip > 0`` closes the picker. Pickers stay inside the workspace
``PICKER_LOW .. PICKER_HIGH``.

The particle mass is uniform, so it does not change the motion of a position-based cloth (constraints
weight particles by inverse mass); ``mass`` is kept in the params as the cloth's total mass, for
reporting and for future forces.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.cloth import collision, fused
from jarena.arenas.cloth.collision import Vec
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.spec import Box

MAX_PICKER_STEP = 1.5
"""Largest picker displacement per control step along each axis, metres (the control's bound)."""
PICKER_LOW = np.array([-1.0, -1.0, 0.0], np.float32)
PICKER_HIGH = np.array([1.0, 1.0, 1.0], np.float32)
READY_HEIGHT = 0.3
"""Height of the pickers' ready pose above the origin, metres: where they start and where primitives end."""


@struct.dataclass
class ClothState:
    """One cloth and its pickers.

    Attributes:
      positions: float32 (N, 3) particle positions, metres, z up.
      velocities: float32 (N, 3), m/s.
      picker_positions: float32 (K, 3).
      picker_closed: bool (K,).
      held: int32 (K, G), the particles each picker holds (nearest first), -1 for empty slots.
      held_offsets: float32 (K, G, 3), held particle minus picker position, fixed at the grasp.
      collision_overflow: int32, particles the self-collision search could not read in the last step
        (more than its candidate slots, see :func:`.collision.neighbour_list`): 0 unless the cloth is piled
        many layers deep, where some close pairs then go unchecked. Reported in the tasks' metrics.
      mesh: the particle grid (static), for agents that read the state (oracles, planners).
    """

    positions: jax.Array
    velocities: jax.Array
    picker_positions: jax.Array
    picker_closed: jax.Array
    held: jax.Array
    held_offsets: jax.Array
    collision_overflow: jax.Array | int = 0
    mesh: ClothMesh | None = struct.field(pytree_node=False, default=None)

    @property
    def grasped(self) -> jax.Array:
        """bool (N,): the particle is held by a picker."""
        n = self.positions.shape[0]
        return jnp.zeros((n,), bool).at[_scatter_index(self.held, n)].set(True, mode="drop")


@struct.dataclass
class ClothParams:
    """Physical constants (float32 scalars; vmap them for domain randomisation).

    Attributes:
      mass: total mass of the cloth, kg (SoftGym's 0.5); see the module note.
      stretch_compliance: XPBD compliance of the distance constraints between grid neighbours, m/N (0: rigid).
      shear_compliance: XPBD compliance of the distance constraints between diagonal neighbours, m/N (0: rigid).
      bend_compliance: XPBD compliance of the distance constraints between neighbours two apart, m/N (0: rigid).
      damping: velocity damping, 1/s (velocities decay as ``exp(-damping t)``; FleX's 1.0).
      friction: Coulomb friction coefficient with the floor (SoftGym's dynamic friction 0.75).
      self_friction: Coulomb friction coefficient between touching layers of the cloth. SoftGym's particle
        friction is 1.0; position-based friction is bounded by the penetration depth, which in a pile
        overstates the normal force, and at 1.0 layers of a crumpled cloth stick together (measured: the
        corner-pulling oracle flattens fewer cloths), hence 0.3.
      gravity: m/s^2 along -z.
      particle_radius: particles rest this far above the floor, metres.
      self_collision_distance: the closest two non-adjacent particles may come, metres.
      grasp_radius: a closing picker grasps particles within this distance in x-y, metres (SoftGym's picker
        radius 0.015 + particle radius 0.00625 + threshold 0.007).
      grasp_depth: ... and at most this far below the highest of them, metres: a pinch from above takes the
        top layer (default: 0.6 x spacing, less than the 0.8 x spacing between layers). SoftGym's sphere
        takes every layer within its radius; a large ``grasp_depth`` comes close to that.
    """

    mass: jax.Array = 0.5
    stretch_compliance: jax.Array = 0.0
    shear_compliance: jax.Array = 1e-6
    bend_compliance: jax.Array = 1e-4
    damping: jax.Array = 1.0
    friction: jax.Array = 0.75
    self_friction: jax.Array = 0.3
    gravity: jax.Array = 9.81
    particle_radius: jax.Array = 0.004
    self_collision_distance: jax.Array = 0.008
    grasp_radius: jax.Array = 0.028
    grasp_depth: jax.Array = 0.006


@dataclasses.dataclass(frozen=True)
class ClothPhysics:
    """Static settings of the simulation (shapes and loop counts, fixed at build time).

    Attributes:
      mesh: the particle grid.
      num_pickers: K.
      max_held: G, the most particles one picker holds (the nearest to its centre within the grasp radius).
      dt: seconds per control step (SoftGym's 0.01).
      substeps: XPBD substeps per control step.
      solver: how the substeps run, a key of :data:`SOLVERS`, or ``"auto"``: ``fused`` on a GPU, ``xla``
        elsewhere.
    """

    mesh: ClothMesh
    num_pickers: int = 1
    max_held: int = 32
    dt: float = 0.01
    substeps: int = 8
    solver: str = "auto"

    def __post_init__(self):
        if self.solver != "auto" and self.solver not in SOLVERS:
            raise ValueError(f"unknown cloth solver {self.solver!r}; valid: auto, {', '.join(SOLVERS)}")
        if int(self.num_pickers) < 1:
            raise ValueError(f"a cloth needs at least one picker, got {self.num_pickers}")
        if int(self.substeps) < 1:
            raise ValueError(f"substeps must be at least 1, got {self.substeps}")

    def resolve_solver(self) -> str:
        """The key of :data:`SOLVERS` this cloth's steps use (``auto``: ``fused`` on a GPU, else ``xla``)."""
        if self.solver != "auto":
            return self.solver
        return "fused" if jax.default_backend() == "gpu" else "xla"

    def default_params(self) -> ClothParams:
        """SoftGym-like constants; collision and contact distances scale with the mesh spacing."""
        s = self.mesh.spacing
        return jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float32),
                                      ClothParams(particle_radius=0.4 * s, self_collision_distance=0.8 * s,
                                                 grasp_depth=0.6 * s))

    @property
    def control_spec(self) -> Box:
        k = int(self.num_pickers)
        high = np.tile(np.array([MAX_PICKER_STEP] * 3 + [1.0], np.float32), (k, 1))
        return Box(-high, high, (k, 4), jnp.float32)

    def ready_positions(self) -> jax.Array:
        """float32 (K, 3): the pickers' ready pose, above the origin at ``READY_HEIGHT``."""
        return jnp.tile(jnp.array([0.0, 0.0, READY_HEIGHT], jnp.float32), (int(self.num_pickers), 1))

    def state_from_positions(self, positions: jax.Array) -> ClothState:
        """A cloth at rest at ``positions`` (N, 3) with open pickers at the ready pose."""
        k, g = int(self.num_pickers), int(self.max_held)
        positions = jnp.asarray(positions, jnp.float32)
        return ClothState(positions=positions, velocities=jnp.zeros_like(positions),
                          picker_positions=self.ready_positions(), picker_closed=jnp.zeros((k,), bool),
                          held=jnp.full((k, g), -1, jnp.int32), held_offsets=jnp.zeros((k, g, 3), jnp.float32),
                          collision_overflow=jnp.zeros((), jnp.int32), mesh=self.mesh)

    # ------------------------------------------------------------------ one control step
    def step(self, state: ClothState, control: jax.Array, params: ClothParams) -> ClothState:
        """Advances the cloth by ``dt``: pickers grasp or release, move by ``control[:, :3]``, cloth follows.

        The params pass an optimization barrier: a caller's ``jit`` holding them as constants would fold them at
        compile time, a last-bit difference that a crumpled cloth grows to millimetres within a few actions."""
        params = jax.lax.optimization_barrier(params)
        control = jnp.asarray(control, jnp.float32)
        delta = jnp.clip(control[:, :3], -MAX_PICKER_STEP, MAX_PICKER_STEP)
        closed = control[:, 3] > 0
        held, offsets = self._grasp(state, closed, params)
        start = state.picker_positions
        end = jnp.clip(start + delta, PICKER_LOW, PICKER_HIGH)
        n = self.mesh.num_particles
        flat_held = _scatter_index(held, n)
        inv_mass = jnp.ones((n,), jnp.float32).at[flat_held].set(0.0, mode="drop")
        # each held particle's picker and offset, so that the substeps place held particles without a scatter
        holder = jnp.full((n,), -1, jnp.int32).at[flat_held].set(
            jnp.repeat(jnp.arange(held.shape[0], dtype=jnp.int32), held.shape[1]), mode="drop")
        offset = tuple(jnp.zeros((n,), jnp.float32).at[flat_held].set(offsets[..., a].ravel(), mode="drop")
                       for a in range(3))
        h = self.dt / self.substeps
        solver = SOLVERS[self.resolve_solver()]
        neighbours, overflow = solver.neighbours(self.mesh, state.positions, 2.0 * params.self_collision_distance)
        tether_to, tether_length = self._tethers(held)
        scalars = jnp.stack([jnp.asarray(s, jnp.float32) for s in (
            params.stretch_compliance / (h * h), params.shear_compliance / (h * h), params.bend_compliance / (h * h),
            jnp.exp(-params.damping * h), -params.gravity * h, jnp.float32(h), params.particle_radius,
            params.friction, params.self_collision_distance, params.self_friction)])
        x, v = solver.substeps(
            self.mesh, self.substeps, collision.components(state.positions), collision.components(state.velocities),
            inv_mass, holder, offset, start, end, tether_to, tether_length, neighbours, scalars)
        return ClothState(positions=jnp.stack(x, axis=-1), velocities=jnp.stack(v, axis=-1), picker_positions=end,
                          picker_closed=closed, held=held, held_offsets=offsets, collision_overflow=overflow,
                          mesh=self.mesh)

    def _grasp(self, state: ClothState, closed: jax.Array, params: ClothParams):
        """What each picker holds after opening (release all) or closing (grasp the nearest free particles)."""
        n, g = self.mesh.num_particles, int(self.max_held)
        keeps = closed & state.picker_closed
        held = jnp.where(keeps[:, None], state.held, -1)
        offsets = jnp.where(keeps[:, None, None], state.held_offsets, 0.0)
        taken = jnp.zeros((n,), bool).at[_scatter_index(held, n)].set(True, mode="drop")
        closing = closed & ~state.picker_closed
        for k in range(int(self.num_pickers)):  # K is small; pickers grasp in order, never the same particle
            # the top layer under the picker: free particles within the radius in x-y, at most grasp_depth
            # below the highest of them, if the picker reaches down to that surface
            p = state.picker_positions[k]
            gap = state.positions[:, :2] - p[:2]
            d_xy = jnp.sqrt(collision.dot(gap, gap))
            under = (d_xy <= params.grasp_radius) & ~taken
            top = jnp.max(jnp.where(under, state.positions[:, 2], -jnp.inf))
            ok = closing[k] & under & (state.positions[:, 2] >= top - params.grasp_depth) & (
                p[2] <= top + params.grasp_radius)
            d = d_xy
            score, idx = jax.lax.top_k(jnp.where(ok, -d, -jnp.inf), min(g, n))
            got = jnp.isfinite(score)
            idx = jnp.where(got, idx, -1).astype(jnp.int32)
            if g > n:
                idx = jnp.pad(idx, (0, g - n), constant_values=-1)
                got = jnp.pad(got, (0, g - n))
            new_offsets = jnp.where(got[:, None], state.positions[jnp.maximum(idx, 0)] - state.picker_positions[k], 0.0)
            held = held.at[k].set(jnp.where(closing[k], idx, held[k]))
            offsets = offsets.at[k].set(jnp.where(closing[k], new_offsets, offsets[k]))
            taken = taken.at[_scatter_index(idx, n)].set(True, mode="drop")
        return held, offsets

    def _tethers(self, held: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Each particle's tether to each picker: int32 (N, K), the held particle nearest to it on the flat cloth
        (the first of equals in ``held``'s order; -1 where the picker holds none), and float32 (N, K) their
        distance on the flat cloth, metres (inf where none).

        Nearest by squared grid distance, an integer: its square root's order is the same (square roots of distinct
        integers below 2^24 round apart), and ``d2 x G + slot`` makes the search one integer minimum, which XLA
        reduces faster than an argmin."""
        n, g = self.mesh.num_particles, held.shape[1]
        cols = self.mesh.cols
        p, q = jnp.arange(n, dtype=jnp.int32)[:, None, None], jnp.maximum(held, 0)[None]  # (N, 1, 1), (1, K, G)
        di, dj = p // cols - q // cols, p % cols - q % cols
        slot = jnp.arange(g, dtype=jnp.int32)
        none = jnp.iinfo(jnp.int32).max
        nearest = jnp.min(jnp.where(held[None] >= 0, (di * di + dj * dj) * g + slot, none), axis=-1)  # (N, K)
        found = nearest < none
        to = jnp.take_along_axis(held[None], jnp.where(found, nearest % g, 0)[..., None], axis=-1)[..., 0]
        d2 = (nearest // g).astype(jnp.float32)
        return jnp.where(found, to, -1), jnp.where(found, jnp.sqrt(d2) * self.mesh.spacing, jnp.inf)


def _tether(x: Vec, inv_mass: jax.Array, to: jax.Array, length: jax.Array) -> Vec:
    """Pulls each free particle within ``length`` (N, K) of its tether particle ``to`` (N, K; -1: none)."""
    for k in range(to.shape[1]):
        anchor = jnp.maximum(to[:, k], 0)
        diff = [c - c[anchor] for c in x]
        dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
        over = jnp.where((to[:, k] >= 0) & (inv_mass > 0), jnp.maximum(dist - length[:, k], 0.0), 0.0)
        x = tuple(c - (over / dist) * d for c, d in zip(x, diff, strict=True))
    return x


def _solve_constraints(mesh: ClothMesh, x: Vec, inv_mass: jax.Array, alphas: dict[str, jax.Array]) -> Vec:
    """One Gauss-Seidel pass over the 12 constraint colours; ``alphas``: compliance / h^2 per kind."""
    grid = tuple(c.reshape(mesh.rows, mesh.cols) for c in x)
    w = inv_mass.reshape(mesh.rows, mesh.cols)
    for pair in _constraint_pairs(mesh.rows, mesh.cols):
        grid = _solve_pairs(grid, w, pair, pair.length * mesh.spacing, alphas[pair.kind])
    return tuple(c.ravel() for c in grid)


def _floor(x: Vec, x_prev: Vec, inv_mass: jax.Array, radius: jax.Array, friction: jax.Array) -> Vec:
    """Keeps free particles at least ``radius`` above z = 0, with Coulomb friction."""
    depth = jnp.maximum(radius - x[2], 0.0) * inv_mass
    tangential = [c - p for c, p in zip(x[:2], x_prev[:2], strict=True)]
    speed = jnp.sqrt(collision.dot_list(tangential, tangential))
    scale = jnp.clip(1.0 - friction * depth / jnp.maximum(speed, 1e-12), 0.0, 1.0)
    xy = [jnp.where(depth > 0, p + t * scale, c)
          for c, p, t in zip(x[:2], x_prev[:2], tangential, strict=True)]
    return (*xy, x[2] + depth)


def substeps_xla(mesh: ClothMesh, substeps: int, x: Vec, v: Vec, inv_mass, holder, offset: Vec, start, end,
                 tether_to, tether_length, neighbours, scalars) -> tuple[Vec, Vec]:
    """The substeps of one control step as jax.numpy (arguments and results as :func:`.fused.run_substeps`, but
    ``neighbours``: int32 (N, M) from :func:`neighbours_xla`)."""
    share = collision.pair_shares(inv_mass, neighbours)
    s = dict(zip(fused.SCALARS, scalars, strict=True))
    h = s["h"]
    alphas = {"stretch": s["alpha_stretch"], "shear": s["alpha_shear"], "bend": s["alpha_bend"]}

    def substep(k, xv):
        x, v = xv
        frac = (k + 1.0) / substeps
        pickers = start + frac * (end - start)
        x_prev = x
        v = tuple(c * s["decay"] for c in v)
        v = (v[0], v[1], v[2] + s["fall"])
        x = tuple(c + u * h for c, u in zip(x, v, strict=True))
        x = tuple(jnp.where(holder >= 0, pickers[jnp.maximum(holder, 0), a] + offset[a], x[a])
                  for a in range(3))
        x = _solve_constraints(mesh, x, inv_mass, alphas)
        x = _tether(x, inv_mass, tether_to, tether_length)
        x = collision.separate(x, x_prev, share, neighbours, s["collision_distance"], s["self_friction"])
        x = _floor(x, x_prev, inv_mass, s["particle_radius"], s["friction"])
        return x, tuple((c - p) / h for c, p in zip(x, x_prev, strict=True))

    return jax.lax.fori_loop(0, substeps, substep, (tuple(x), tuple(v)))


PAIRWISE_PARTICLES = 384
"""Cloths of at most this many particles find their close pairs by :func:`.collision.neighbour_list_pairwise`
(the same list, faster for small cloths on a CPU), larger ones by :func:`.collision.neighbour_list`."""


def neighbours_xla(mesh: ClothMesh, x: jax.Array, radius: jax.Array) -> tuple[jax.Array, jax.Array]:
    """:func:`.collision.neighbour_list` of a cloth's positions ``x`` (N, 3), grid neighbours excluded."""
    cols = mesh.cols

    def adjacent(i, j):
        return (jnp.abs(i // cols - j // cols) <= 1) & (jnp.abs(i % cols - j % cols) <= 1)

    small = 16 <= mesh.num_particles <= PAIRWISE_PARTICLES  # 16: the list's entries per particle
    return (collision.neighbour_list_pairwise if small else collision.neighbour_list)(x, radius, adjacent)


@dataclasses.dataclass(frozen=True)
class Solver:
    """How a control step runs: ``neighbours(mesh, x, radius) -> (pairs, overflow)``, the self-collision pairs
    (M per particle, int32, laid out as the solver's ``substeps`` reads them: (N, M) for ``xla``); ``substeps(mesh,
    substeps, x, v, ..., pairs, scalars) -> (x, v)``, the substeps (arguments as :func:`substeps_xla`)."""

    neighbours: Callable
    substeps: Callable


SOLVERS = {"xla": Solver(neighbours_xla, substeps_xla), "fused": Solver(fused.neighbour_rows, fused.run_substeps)}
"""How a control step runs: ``xla`` (jax.numpy, any backend) or ``fused`` (Pallas kernels, one program per
cloth, :mod:`.fused`: the neighbour search and the substeps; on a CPU they run in Pallas' interpreter, for
tests only). Both compute the same pairs and the same arithmetic in the same order."""


def _scatter_index(held: jax.Array, n: int) -> jax.Array:
    """Flat particle indices of ``held`` with empty slots (-1) sent out of bounds (``n``), for ``mode="drop"``.

    (A -1 index would wrap around to the last particle.)
    """
    return jnp.where(held >= 0, held, n).ravel()


@dataclasses.dataclass(frozen=True)
class _Pairs:
    """A set of disjoint grid pairs ``(i, j) - (i + di, j + dj)`` solved together (one colour)."""

    kind: str
    di: int
    dj: int
    length: float  # rest length in units of spacing
    mask: np.ndarray  # bool over the (first particle's) pair grid: which pairs belong to this colour


@functools.cache
def _constraint_pairs(rows: int, cols: int) -> tuple[_Pairs, ...]:
    """The 12 colours of :data:`.fused.COLOURS`: stretch along rows and columns, both shear diagonals, bending
    along rows and columns."""
    out = []
    for di, dj, axis, div, colour, kind in fused.COLOURS.tolist():
        i, j = np.meshgrid(np.arange(rows - di), np.arange(cols - abs(dj)), indexing="ij")
        if dj < 0:
            j = j + 1  # first particle (i, j), second (i + 1, j - 1)
        along = (i, j)[axis]
        out.append(_Pairs(fused.KINDS[kind], di, dj, float(np.hypot(di, dj)), (along // div) % 2 == colour))
    return tuple(out)


def _solve_pairs(grid: Vec, w: jax.Array, pairs: _Pairs, rest: float, alpha: jax.Array) -> Vec:
    """One XPBD projection of the disjoint distance constraints ``pairs`` on ``grid`` (3 of (rows, cols))."""
    rows, cols = w.shape
    di, dj = pairs.di, pairs.dj
    if dj >= 0:
        a = (slice(0, rows - di), slice(0, cols - dj))
        b = (slice(di, rows), slice(dj, cols))
    else:
        a = (slice(0, rows - di), slice(-dj, cols))
        b = (slice(di, rows), slice(0, cols + dj))
    wa, wb = w[a], w[b]
    diff = [c[a] - c[b] for c in grid]
    dist = jnp.sqrt(collision.dot_list(diff, diff) + 1e-12)
    denom = wa + wb + alpha
    lam = jnp.where(pairs.mask & (denom > 0), -(dist - rest) / jnp.maximum(denom, 1e-12), 0.0)
    scale = lam / dist

    def place(d, s):
        return jnp.pad(d, [(s[0].start, rows - s[0].stop), (s[1].start, cols - s[1].stop)])

    return tuple(c + place(wa * (scale * d), a) + place(-wb * (scale * d), b) for c, d in zip(grid, diff, strict=True))
