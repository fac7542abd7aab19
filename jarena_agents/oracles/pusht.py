"""``oracle_pusht``: an analytic pusher for ``pusht`` arenas (greedy frictionless pushes, ways around the block).

The block keeps no momentum in ``pusht`` (its velocity is damped to 0 every physics step) and its contacts are
frictionless, so it moves only while the disc pushes it, and then as one impulse along the contact normal moves
a free body: a push of ``s`` units along the inward normal ``n`` at a point ``r`` from the centre of gravity
changes the block's pose (centre, angle) by ``(n, k / I) s / (1 + k^2 / I)``, ``k = r x n`` (mass 1).
Each action, from the privileged scene, in the block's frame:

1. the error: the centre of gravity's offset to the goal's and the turn to the goal's angle (wrapped), the turn
   weighted by ``length`` (units of translation per radian: coverage falls about as fast with either);
2. for each of 34 contact points on the T's outline (:data:`CONTACTS`, placed so that the disc on a contact's
   normal touches no other face), the push that best reduces the weighted error along its twist (at most
   ``push_max`` units) and how much it reduces it (:func:`contact_pushes`);
3. the contact with the best reduction per action, counting the actions to get there: sliding along the face the
   disc is on, straight to the contact's approach point (where its normal leaves the block's convex hull grown by
   the disc's radius and ``clearance``) where that clears the hull, else around the hull the shorter way whose
   points, held in the plane, keep the disc off the T by its radius and the clearance; then in along the normal;
4. the target point on that way: ``push_gain`` times the push past the face, in the contact's corridor; beside
   the contact on its face; out along the nearest face's normal from inside the grown hull elsewhere; the
   approach point; or about ``lookahead`` units ahead around the hull (the longest of three steps whose straight
   way keeps the disc off the T).

It needs no randomness and reads only the pusher's and the block's positions and ``info.goal``, so an episode
gets the same actions for any key and in any batch. It succeeds on all 100 eval episodes in 74 actions on average
and on 5,999 of 6,000 others (``docs/arenas/pusht.md``).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.pusht import geometry
from jarena.arenas.pusht.physics import PushTParams
from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import Range, make_config, positive, ranged
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class PushTOracleConfig:
    length: float = positive(60.0)  # units of translation that weigh as much as a radian of turn
    push_max: float = positive(50.0)  # the deepest push aimed at in one action, units
    push_gain: float = positive(1.5)  # the target goes this many times the wanted push past the contact
    clearance: float = ranged(6.0, Range(0.0, 40.0))  # units between the disc and the block's hull on the way
    lookahead: float = positive(80.0)  # units ahead along a path around the block
    corridor: float = positive(6.0)  # units off a contact's normal within which the disc goes in and pushes
    speed: float = positive(30.0)  # units per action, to count the steps of a path
    push_steps: float = positive(3.0)  # actions a push takes besides its travel


def _outline() -> tuple[np.ndarray, np.ndarray]:
    """The T's outline in its body frame, counter-clockwise: the faces' start and end points, (8, 2) each."""
    corners = np.array([[-60, 0], [60, 0], [60, 30], [15, 30], [15, 120], [-15, 120], [-15, 30], [-60, 30]],
                       np.float32)
    return corners, np.roll(corners, -1, axis=0)


FACE_START, FACE_END = _outline()
FACE_NORMALS = np.stack([FACE_END[:, 1] - FACE_START[:, 1], FACE_START[:, 0] - FACE_END[:, 0]], -1)
FACE_NORMALS = (FACE_NORMALS / np.linalg.norm(FACE_NORMALS, axis=-1, keepdims=True)).astype(np.float32)
"""float32 (8, 2): each face's outward normal (bar bottom, right end, right bar top, stem right, stem tip, stem
left, left bar top, left end)."""

_ALONG = {  # per face: where its contacts lie, as x (faces along x) or y (faces along y) in the body frame
    0: (-55, -45, -30, -15, 0, 15, 30, 45, 55), 1: (5, 15, 25), 2: (35, 47, 57), 3: (48, 65, 85, 100, 112),
    4: (10, 0, -10), 5: (112, 100, 85, 65, 48), 6: (-57, -47, -35), 7: (25, 15, 5)}


def _contacts() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The candidate contacts: points (K, 2) on the outline, their outward normals (K, 2) and faces (K,).

    Contacts on the bar's top faces lie at least a radius from the stem, and those on the stem's sides at least a
    radius above the bar, so that the disc on a contact's normal touches nothing else."""
    points, faces = [], []
    for face, values in _ALONG.items():
        start = FACE_START[face]
        for v in values:
            points.append([v, start[1]] if FACE_START[face][1] == FACE_END[face][1] else [start[0], v])
            faces.append(face)
    faces = np.array(faces, np.int32)
    return np.array(points, np.float32), FACE_NORMALS[faces], faces


CONTACTS, NORMALS, FACES = _contacts()
"""The 34 candidate contacts in the body frame: points float32 (34, 2) on the outline, their outward normals
float32 (34, 2) and their faces int32 (34,) (indices into :data:`FACE_NORMALS`)."""
COG = np.asarray(geometry.CENTRE_OF_GRAVITY, np.float32)


def _hull(clearance: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The T's convex hull grown by ``radius + clearance``: its edges' outward normals (6, 2) and offsets (6,),
    inside where ``normals @ x < offsets``."""
    start, end = geometry.HULL, np.roll(geometry.HULL, -1, axis=0)
    normals = np.stack([end[:, 1] - start[:, 1], start[:, 0] - end[:, 0]], -1)
    normals = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    return normals.astype(np.float32), (np.sum(normals * start, -1) + radius + clearance).astype(np.float32)


def _exit(points, directions, normals, offsets):
    """How far rays from ``points`` (..., 2) along ``directions`` (..., 2) go before they leave a convex polygon
    (``normals`` (E, 2), ``offsets`` (E,)) that holds them."""
    along = directions @ normals.T  # (..., E)
    room = offsets - points @ normals.T
    return jnp.min(jnp.where(along > 1e-6, room / jnp.where(along > 1e-6, along, 1.0), jnp.inf), -1)


def _segment_clear(start, end, normals, offsets):
    """bool: whether the segment from ``start`` to ``end`` (2,) misses a convex polygon (Cyrus-Beck clipping)."""
    num = offsets - normals @ start
    den = normals @ (end - start)
    parallel = jnp.abs(den) < 1e-9
    t = num / jnp.where(parallel, 1.0, den)
    enter = jnp.max(jnp.where(den < -1e-9, t, 0.0))
    leave = jnp.min(jnp.where(den > 1e-9, t, 1.0))
    return jnp.any(parallel & (num < 0)) | (enter >= leave)


def _distance(points):
    """The distance from body-frame points (..., 2) to the T (0 inside it)."""
    low, high = geometry.BOXES[:, 0::2], geometry.BOXES[:, 1::2]
    gap = points[..., None, :] - jnp.clip(points[..., None, :], low, high)
    return jnp.sqrt(jnp.min(jnp.sum(gap * gap, -1), -1))


def _nearest_face(p):
    """The face of the outline nearest a body-frame point ``p`` (2,), and the unit direction from it to ``p``."""
    edge = FACE_END - FACE_START
    t = jnp.clip(jnp.sum((p - FACE_START) * edge, -1) / np.sum(edge * edge, -1), 0.0, 1.0)
    gap = p - (FACE_START + t[:, None] * edge)
    distance = jnp.sqrt(jnp.sum(gap * gap, -1))
    face = jnp.argmin(distance)
    radial = (p - COG) / jnp.maximum(jnp.linalg.norm(p - COG), 1e-6)  # on the outline itself: away from the centre
    return face, jnp.where(distance[face] > 1e-3, gap[face] / jnp.maximum(distance[face], 1e-6), radial)


def _ring(angle, normals, offsets, clearance):
    """Points (..., 2) ``clearance`` outside the grown hull in the directions ``angle`` (...) from the centre of
    gravity, and their distances from it (...)."""
    u = jnp.stack([jnp.cos(angle), jnp.sin(angle)], -1)
    distance = _exit(jnp.broadcast_to(COG, u.shape), u, normals, offsets) + clearance
    return COG + distance[..., None] * u, distance


def _rotate(angle, v):
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], -1)


def contact_pushes(error: jax.Array, length: float, push_max: float, inertia: float = geometry.INERTIA
                   ) -> tuple[jax.Array, jax.Array]:
    """The push at each contact that best reduces the error, and by how much.

    Args:
      error: float32 (3,) the block's error in its own frame: the centre of gravity's offset to the goal's, and
        the turn to the goal's angle (radians).
      length: units of translation that weigh as much as a radian (the error's norm is
        ``|offset|^2 + length^2 turn^2``).
      push_max: the longest push, units.
      inertia: the block's moment of inertia about its centre of gravity (mass 1).

    Returns:
      float32 (K,) each contact's push (units of the disc's travel along its normal, >= 0) and float32 (K,) the
      fall of the squared error norm it brings under the twist model (module docstring).
    """
    inward = -NORMALS
    arm = CONTACTS - COG
    moment = arm[:, 0] * inward[:, 1] - arm[:, 1] * inward[:, 0]
    twist = np.concatenate([inward, (moment / inertia)[:, None]], -1) / (1 + moment**2 / inertia)[:, None]
    weight = np.array([1.0, 1.0, length**2], np.float32)
    a = (twist * weight).astype(np.float32) @ error
    b = np.sum(twist * twist * weight, -1).astype(np.float32)
    push = jnp.clip(a / b, 0.0, push_max)
    return push, 2 * push * a - push**2 * b


def target(pusher: jax.Array, pose: jax.Array, goal: jax.Array, cfg: PushTOracleConfig,
           params: PushTParams | None = None) -> jax.Array:
    """One arena's action, float32 (2,): the pusher's target point in the plane (module docstring).

    Args:
      pusher: float32 (2,) the disc's centre.
      pose: float32 (3,) the block's pose ``(x, y, angle)`` (its body origin, as ``pusht_env``).
      goal: float32 (3,) the goal pose.
      cfg: the oracle's config.
      params: the scene's constants (the disc's radius and the block's inertia are read; default: the arena's).
    """
    params = PushTParams() if params is None else params
    radius = float(params.pusher_radius)
    normals, offsets = _hull(cfg.clearance, radius)

    def to_plane(q):
        return _rotate(pose[2], q) + pose[:2]

    def to_body(q):
        return _rotate(-pose[2], q - pose[:2])

    def held(q):  # body-frame points where the pusher goes when sent there: its targets are clipped to the plane
        return to_body(jnp.clip(to_plane(q), 0.0, geometry.SIZE))

    def in_plane(q):
        w = to_plane(q)
        return jnp.all((w >= 0.0) & (w <= geometry.SIZE), -1)

    # 1-2. the error in the block's frame, and each contact's push
    offset = to_body(goal[:2] + _rotate(goal[2], COG)) - COG
    turn = jnp.mod(goal[2] - pose[2] + jnp.pi, 2 * jnp.pi) - jnp.pi
    push, reduction = contact_pushes(jnp.concatenate([offset, turn[None]]), cfg.length, cfg.push_max,
                                     float(params.block_inertia))

    # 3. the steps to each contact: along its face, in along its normal, straight to its approach point or around
    p = to_body(pusher)
    depth = _exit(CONTACTS, NORMALS, normals, offsets) + 2.0  # where the normal leaves the grown hull
    approach = CONTACTS + NORMALS * depth[:, None]
    along = jnp.sum((p - CONTACTS) * NORMALS, -1)
    across = jnp.sum((p - CONTACTS) * NORMALS[:, ::-1] * np.array([1.0, -1.0], np.float32), -1)
    face, away = _nearest_face(p)
    inside = jnp.all(normals @ p < offsets)
    on_face = (face == FACES) & (along > radius - 3.0) & (along < radius + cfg.clearance)
    in_corridor = (jnp.abs(across) < cfg.corridor) & (along > radius - 3.0) & (along < depth + 3.0)
    clear = jax.vmap(lambda e: _segment_clear(p, e, normals, offsets))(approach)
    start = jnp.arctan2(p[1] - COG[1], p[0] - COG[0])
    ccw = jnp.mod(jnp.arctan2(approach[:, 1] - COG[1], approach[:, 0] - COG[0]) - start, 2 * jnp.pi)
    sweeps = jnp.stack([ccw, 2 * jnp.pi - ccw], -1)  # (K, 2): counter-clockwise, clockwise
    fractions = jnp.linspace(0.0, 1.0, 17)
    ring, ring_radius = _ring(start + np.array([[1.0], [-1.0]]) * sweeps[..., None] * fractions, normals, offsets,
                              cfg.clearance)  # (K, 2, 17, 2)
    # a way round is open where the pusher, held in the plane, stays its radius and the clearance off the T
    open_way = jnp.all(_distance(held(ring)) > radius + cfg.clearance, -1)
    arc = jnp.where(open_way, sweeps * jnp.mean(ring_radius, -1), jnp.inf)
    direction = jnp.argmin(arc, -1)  # (K,): 0 counter-clockwise, 1 clockwise
    around = jnp.min(arc, -1) + jnp.abs(jnp.linalg.norm(p - COG) - jnp.linalg.norm(approach - COG, axis=-1))
    travel = jnp.where(on_face | in_corridor, jnp.abs(across) + jnp.abs(along - radius),
                       jnp.where(clear, jnp.linalg.norm(approach - p, axis=-1), around) + depth - radius)
    reachable = in_plane(CONTACTS + NORMALS * radius) & in_plane(approach) & jnp.isfinite(travel)
    rate = reduction / (cfg.push_steps + (push + travel) / cfg.speed)
    best = jnp.argmax(jnp.where(reachable, rate, -1.0))

    # 4. the target point on the way to the chosen contact
    contact, normal = jnp.asarray(CONTACTS)[best], jnp.asarray(NORMALS)[best]
    sweep = sweeps[best, direction[best]]
    step = jnp.minimum(cfg.lookahead / jnp.maximum(jnp.linalg.norm(p - COG), 1.0), sweep)
    steps = step * np.array([1.0, 0.5, 0.25], np.float32)
    # a chord to the ring bulges inwards: the points go out by 1 / cos(step / 2) (which clears a circle), and the
    # longest step whose straight way keeps the disc off the T is taken
    points, _ = _ring(start + jnp.where(direction[best] == 0, 1.0, -1.0) * steps, normals, offsets, cfg.clearance)
    points = held(COG + (points - COG) / jnp.cos(jnp.minimum(steps, 2.0) / 2)[:, None])
    ways = jnp.all(_distance(p + fractions[:, None, None] * (points - p)) > radius + 2.0, 0)
    orbit = points[jnp.where(ways.any(), jnp.argmax(ways), 0)]
    aim = jnp.where(clear[best], approach[best], orbit)
    aim = jnp.where(inside, p + away * cfg.lookahead, aim)
    aim = jnp.where(on_face[best], contact + normal * (radius + 2.0), aim)
    aim = jnp.where(in_corridor[best], contact + normal * (radius - cfg.push_gain * push[best]), aim)
    return jnp.clip(to_plane(aim), 0.0, geometry.SIZE)


def make_pusht_oracle(config=None) -> Agent:
    """The oracle for ``pusht`` arenas (module docstring) with the default physical constants."""
    cfg = make_config(PushTOracleConfig, config, agent="oracle_pusht")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        physics = privileged.physics
        pose = jnp.concatenate([physics.block, physics.block_angle[..., None]], -1)
        batch = info.goal.shape[:-1]
        count = math.prod(batch)
        flat = [x.reshape((count,) + x.shape[len(batch):]) for x in (physics.pusher, pose, info.goal)]
        actions = jax.vmap(lambda p, q, g: target(p, q, g, cfg))(*flat)
        return actions.reshape(batch + (2,)), state

    return Agent(name="oracle_pusht", init=init, act=act, privileged=True, made_for=("pusht",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_pusht", make_pusht_oracle, tags=("oracle",))
