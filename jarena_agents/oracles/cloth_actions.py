"""What the cloth oracles share: turning pick and place points into a pick-and-place tool's action."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jarena.arenas.cloth import camera as camera_lib
from jarena.arenas.cloth import tools as tools_lib
from jarena.arenas.cloth.collision import dot
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.arenas.cloth.physics import ClothParams
from jarena_agents.config import ConfigError
from jarena_agents.planners.agent import resolve_model


def frame_of(privileged, agent: str) -> str:
    """``"pixel"`` or ``"world"``: the frame of the arena's pick-and-place tool (a clear error without one)."""
    coordinates = tools_lib.coordinates_of(privileged.tool)
    if getattr(privileged.physics, "mesh", None) is None or coordinates is None:
        raise TypeError(f"{agent} acts on cloth arenas with a pick-and-place tool "
                        "(action:pixel_pick_and_place(K) or pick_and_place(K))")
    return coordinates


def encode(pick: jax.Array, place: jax.Array, coordinates: str) -> jax.Array:
    """float32 (4 K,): the action that picks at ``pick`` and places at ``place`` (K, 2) world x-y, metres.

    In the tool's frame (``coordinates``), with the default heights and camera of
    :mod:`jarena.arenas.cloth.tools`, clipped to [-1, 1].
    """
    defaults = tools_lib.PickPlaceParams()
    if coordinates == "pixel":
        camera = camera_lib.CameraParams()

        def to_frame(xy, z):
            return camera_lib.world_to_pixel(jnp.concatenate([xy, jnp.full(xy.shape[:-1] + (1,), z)], -1), camera)
    else:
        def to_frame(xy, z):
            return xy / defaults.workspace
    action = jnp.concatenate([to_frame(pick, defaults.pick_height), to_frame(place, defaults.place_height)], -1)
    return jnp.clip(action, -1.0, 1.0).reshape(-1)


def one_picker(pick: jax.Array, place: jax.Array, pickers: int, coordinates: str) -> jax.Array:
    """float32 (P, 4 K): P actions each moving one picker from ``pick`` to ``place`` (P, 2) world x-y, metres;
    the other ``K - 1`` pickers idle."""
    single = jax.vmap(lambda p, q: encode(p[None], q[None], coordinates))(pick, place)
    return jnp.concatenate([single, jnp.tile(idle(pickers - 1), (single.shape[0], 1))], -1)


def lookahead_model(agent: str, cfg, arena, without: str):
    """The exact model of the arena an oracle's lookahead simulates: ``arena``, else the one built from config
    ``arena`` (:func:`jarena_agents.planners.agent.resolve_model`).

    Raises:
      ConfigError: neither given; the message names the ways to give it and ``without`` (what
        ``lookahead=False`` does instead).
    """
    if arena is None and not cfg.arena:
        raise ConfigError(f"agent {agent!r} looks ahead in the arena's own dynamics and needs that arena: pass "
                          "config arena='<arena string>' (the jarena command does), make it with arena=<Arena>, "
                          f"or set lookahead=False for {without}")
    return resolve_model(agent, cfg, arena, None)[0]


def each_score(states, tried: jax.Array, score) -> jax.Array:
    """float32 (B, P): ``score(state, action)`` (a float32 scalar) of each of B states (pytree leaves with a
    leading axis B) and each of its P actions ``tried`` (B, P, 4 K).

    The B x P scores run as one batch, each state repeated P times, rather than a vmap over the P actions
    inside a vmap over the B states: a score that steps the arena (a scan of physics steps, each a loop of
    substeps) is then traced and batched once, not twice over.
    """
    b, p = tried.shape[:2]
    repeated = jax.tree_util.tree_map(lambda x: jnp.repeat(x, p, axis=0), states)
    return jax.vmap(score)(repeated, tried.reshape((b * p,) + tried.shape[2:])).reshape(b, p)


def best_of(states, tried: jax.Array, score) -> jax.Array:
    """float32 (B, 4 K): for each of B states, the action of ``tried`` (B, P, 4 K) with the highest
    :func:`each_score` (the first of equals)."""
    best = jnp.argmax(each_score(states, tried, score), axis=-1)
    return jnp.take_along_axis(tried, best[:, None, None], axis=1)[:, 0]


def idle(num_pickers: int) -> jax.Array:
    """float32 (4 K,): pick and place at the workspace's empty corner (the cloth only settles)."""
    return -jnp.ones((4 * int(num_pickers),), jnp.float32)


def covered(positions: jax.Array, particles: jax.Array, spacing: float) -> jax.Array:
    """bool (H,): whether another layer lies on top of each of ``particles`` (H,) (a pinch would take it)."""
    offset = positions[None, :, :2] - positions[particles, None, :2]
    xy = jnp.sqrt(dot(offset, offset))
    return jnp.any((xy < spacing) & (positions[None, :, 2] > positions[particles, None, 2] + 0.4 * spacing), axis=-1)


def handles(mesh: ClothMesh) -> np.ndarray:
    """int32 (8,): the particles the oracles may pull, the four corners and the four edge midpoints."""
    r, c = mesh.rows - 1, mesh.cols - 1
    points = [(0, 0), (0, c), (r, c), (r, 0), (0, c // 2), (r // 2, c), (r, c // 2), (r // 2, 0)]
    return np.array([mesh.index(i, j) for i, j in points], np.int32)


def edge_handles(mesh: ClothMesh) -> np.ndarray:
    """int32 (16,): :func:`handles` and the eight quarter points of the edges."""
    r, c = mesh.rows - 1, mesh.cols - 1
    quarters = [(0, c // 4), (0, 3 * c // 4), (r // 4, c), (3 * r // 4, c), (r, 3 * c // 4), (r, c // 4),
                (3 * r // 4, 0), (r // 4, 0)]
    return np.concatenate([handles(mesh), np.array([mesh.index(i, j) for i, j in quarters], np.int32)])


def interior_handles(mesh: ClothMesh, side: int) -> np.ndarray:
    """int32 (side^2,): a ``side x side`` grid of particles inside the cloth, at the centres of equal cells
    (none for side 0)."""
    rows = np.round((np.arange(side) + 0.5) * (mesh.rows - 1) / side).astype(int)
    cols = np.round((np.arange(side) + 0.5) * (mesh.cols - 1) / side).astype(int)
    return np.array([mesh.index(i, j) for i in rows for j in cols], np.int32)


def tip_offsets(positions: jax.Array, mesh: ClothMesh) -> jax.Array:
    """float32 (4, 2): for each corner (in :func:`handles`' order), the picker's offset from it,
    x-y metres, that grasps the corner's tip.

    A picker grasps every top-layer particle within the grasp radius (:class:`~jarena.arenas.cloth.physics.
    ClothParams`' default 0.028 m) and carries them as a rigid patch: it does not turn them when the flap turns
    over. The patch, still face up on a flap that is face down, springs over at the release, flinging the
    corner centimetres past its place (on a 40 x 40 cloth the 8 particles of a corner's patch threw it 53-68 mm
    past its goal; the tip alone, 7 mm). So the tip pinch closes ``grasp radius - spacing / 2`` outside the
    corner along the diagonal: the corner is within reach, its grid neighbours are not.
    """
    r, c = mesh.rows - 1, mesh.cols - 1
    corners = handles(mesh)[:4]
    inside = np.array([mesh.index(i, j) for i, j in [(1, 1), (1, c - 1), (r - 1, c - 1), (r - 1, 1)]], np.int32)
    outward = positions[corners, :2] - positions[inside, :2]
    outward = outward / jnp.maximum(jnp.sqrt(dot(outward, outward)), 1e-9)[:, None]
    reach = max(float(ClothParams.grasp_radius) - 0.5 * mesh.spacing, 0.0)
    return jnp.float32(reach) * outward


def pull(positions: jax.Array, handles: jax.Array, targets: jax.Array, eligible: jax.Array, pickers: int,
         spacing: float, coordinates: str) -> tuple[jax.Array, jax.Array]:
    """The oracles' move: pick the ``pickers`` eligible handles farthest from their targets and place them there.

    Args:
      positions: float32 (N, 3) particles.
      handles: int32 (H,) particles that may be pulled.
      targets: float32 (H, 2) where each handle should lie, x-y metres.
      eligible: bool (H,), the handles that may be picked.
      pickers: K, the number of pickers.
      spacing: the mesh's spacing, metres.
      coordinates: the tool's frame.

    Returns:
      float32 (4 K,) the action (handles on top ranked first: a covered one counts a quarter of its distance,
      since a pinch takes the top layer; pickers left without an eligible handle idle), and the largest
      eligible handle's distance to its target, metres.
    """
    offset = positions[handles, :2] - targets
    error = jnp.sqrt(dot(offset, offset))
    ranked = jnp.where(covered(positions, handles, spacing), error * 0.25, error)
    ranked = jnp.where(eligible, ranked, -1.0)
    rank, worst = jax.lax.top_k(ranked, pickers)
    action = encode(positions[handles[worst], :2], targets[worst], coordinates).reshape(pickers, 4)
    action = jnp.where((rank >= 0)[:, None], action, idle(pickers).reshape(pickers, 4))
    return action.reshape(-1), jnp.max(jnp.where(eligible, error, 0.0))
