"""``oracle_cloth_folding``: the scripted fold for the ``cloth`` folding tasks, with privileged particle positions.

Agent-Arena's and SoftGym's folding oracles pick the corners of the folding side and place them where the fold
takes them. This one reads the goal the task puts in ``info.goal`` (the folded particle positions, any of
``side_fold``, ``diagonal_fold``, ``one_corner_inward``), so one oracle serves every fold. Each action:

1. the flat cloth the goal folds (:func:`flat_pose`): the rest grid mapped onto the goal's floor layer;
2. until the episode's first fold, while a handle (corner or edge midpoint, :func:`.cloth_actions.handles`)
   of the floor layer lies more than ``flat_tolerance`` from that flat pose (a crumpled start), flatten: pull
   the handle farthest from its flat position there (as ``oracle_cloth_flattening``, toward this pose);
3. then fold, and never flatten again in the episode (that would undo the fold): the analytic fold picks the
   handle of the folding side farthest from its goal and places it on its goal (``K`` pickers: the ``K``
   worst), preferring handles on top (a covered one counts a quarter: the pickers grasp the top layer);
4. ``lookahead`` (default): try folds in the arena's own step and take the one that leaves the highest reward
   (the lowest normalised fold distance): for each of ``fractions``, the analytic fold, each of the 16 edge
   handles (:func:`.cloth_actions.edge_handles`, one picker; spare pickers idle) and each corner pinched at its
   tip (:func:`.cloth_actions.tip_offsets`) placed that fraction of the way to its goal, and doing nothing
   (:func:`fold_proposals`). A cloth carried at the tool's speed slides on
   after release (its momentum drags the flap past its goal and the floor layer with it), so a place short of
   the goal often folds closer; the lookahead measures that rather than guessing it. Without lookahead: the
   analytic fold, and once every handle is within ``stop_distance`` of its goal, nothing (pick and place at
   the workspace's empty corner).

The lookahead plans with the arena it acts in, as the flattening oracle's: config ``arena`` (the ``jarena``
command sets it) or ``make_cloth_folding_oracle(config, arena=...)``. Actions are in the frame of the arena's
tool, as the flattening oracle's.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from jarena.arenas.cloth.collision import fixed_matmul, fixed_sum
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.agent import Agent
from jarena.core.arena import ArenaSpec
from jarena_agents.config import ConfigError, Range, make_config, ranged
from jarena_agents.oracles import cloth_actions
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class ClothFoldingOracleConfig:
    flat_tolerance: float = ranged(0.04, Range(0.0, 1.0))  # metres: floor-layer handles this far off: flatten first
    stop_distance: float = ranged(0.1, Range(0.0, 1.0))  # metres: without lookahead, every handle this near: stop
    lookahead: bool = True  # try the folds in the arena's own dynamics and take the best
    fractions: tuple = (0.6, 0.7, 0.8, 0.9, 1.0)  # how far toward its goal a proposed fold places a handle
    arena: str = ""  # the arena the lookahead simulates (its build string); the jarena command sets it


@struct.dataclass
class FoldingOracleState:
    """``folding``: bool (B,), whether each arena's episode has begun folding (it flattens before)."""

    folding: jax.Array
    spec: ArenaSpec = struct.field(pytree_node=False)


def floor_layer(goal: jax.Array, mesh: ClothMesh) -> jax.Array:
    """bool (N,): the goal's particles that stay on the floor (the folded layer lies one layer gap above)."""
    return goal[:, 2] < 0.8 * mesh.spacing


def flat_pose(goal: jax.Array, mesh: ClothMesh) -> jax.Array:
    """float32 (N, 2): the flat cloth that ``goal`` (N, 3) folds, x-y metres.

    The affine map from the rest grid to the goal's floor layer in least squares (that layer is where the flat
    cloth lay, and holds at least half of it, so the map is determined), applied to the whole grid.
    """
    material = jnp.concatenate([jnp.asarray(mesh.rest_positions[:, :2]), jnp.ones((mesh.num_particles, 1))], -1)
    weighted = material * floor_layer(goal, mesh).astype(jnp.float32)[:, None]
    # sums in a fixed order (not matmuls, whose order can change with the batch size): the same in any batch
    gram = fixed_sum(weighted[:, :, None] * material[:, None, :], axis=0)
    moment = fixed_sum(weighted[:, :, None] * goal[:, None, :2], axis=0)
    return fixed_matmul(material, jnp.linalg.solve(gram, moment))


def fold_proposals(positions: jax.Array, goal: jax.Array, mesh: ClothMesh, pickers: int, coordinates: str,
                   fractions: tuple[float, ...]) -> jax.Array:
    """The folds the lookahead tries: float32 ``(P, 4 K)``, P = 2 + 21 x len(fractions).

    First the analytic fold and doing nothing; then, for each fraction ``f``, the analytic fold, each of the
    16 edge handles alone placed at ``pick + f (goal - pick)`` (one picker; the spare ones idle), and each of
    the 4 corners pinched at its tip (:func:`.cloth_actions.tip_offsets`) with the corner placed there.
    Handles that stay on the floor in ``goal`` (N, 3) are proposed too: lifting one drags the cloth toward it by
    a few millimetres (a cloth that cannot stretch comes off the floor only by sliding), which can undo the slide
    an earlier fold left.
    """
    corners = jnp.asarray(cloth_actions.handles(mesh))  # the analytic fold's handles: corners and edge midpoints
    edges = jnp.asarray(cloth_actions.edge_handles(mesh))
    moving = ~floor_layer(goal, mesh)
    four = corners[:4]  # the corners alone, pinched at their tips
    tips = cloth_actions.tip_offsets(positions, mesh)

    def toward(handles, f):  # float32 (H, 2): each handle placed the fraction f of the way to its goal
        pick = positions[handles, :2]
        return pick + jnp.float32(f) * (goal[handles, :2] - pick)

    def fold(places):  # float32 (4 K,): the analytic fold onto places (corners and edge midpoints, (H, 2))
        return cloth_actions.pull(positions, corners, places, moving[corners], pickers, mesh.spacing, coordinates)[0]

    actions = [fold(goal[corners, :2])[None], cloth_actions.idle(pickers)[None]]
    for f in fractions:
        actions += [fold(toward(corners, f))[None],
                    cloth_actions.one_picker(positions[edges, :2], toward(edges, f), pickers, coordinates),
                    cloth_actions.one_picker(positions[four, :2] + tips, toward(four, f) + tips, pickers, coordinates)]
    return jnp.concatenate(actions)


def make_cloth_folding_oracle(config=None, arena=None) -> Agent:
    """The oracle for ``cloth|...,task:<fold>`` arenas (``side_fold``, ``diagonal_fold``, ``one_corner_inward``).

    Args:
      config: :class:`ClothFoldingOracleConfig` overrides.
      arena: the arena the lookahead simulates (else the one built from config ``arena``).

    Raises:
      ConfigError: with ``lookahead`` and no arena to simulate, or fractions outside (0, 1.5].
    """
    cfg = make_config(ClothFoldingOracleConfig, config, agent="oracle_cloth_folding")
    fractions = tuple(float(f) for f in cfg.fractions)
    if not fractions or not all(0.0 < f <= 1.5 for f in fractions):
        raise ConfigError(f"config key 'fractions' of agent 'oracle_cloth_folding' must be a non-empty list of "
                          "numbers in (0, 1.5] (how far toward its goal a fold places a handle), "
                          f"got {cfg.fractions!r}")
    model = (cloth_actions.lookahead_model("oracle_cloth_folding", cfg, arena, "the analytic fold alone")
             if cfg.lookahead else None)

    def init(key, spec, num_arenas):
        return FoldingOracleState(folding=jnp.zeros((num_arenas,), bool), spec=spec)

    def reset(state, mask):
        return state.replace(folding=state.folding & ~mask)

    def one(privileged, goal, folding, pickers: int, coordinates: str):
        """One cloth's flattening pull, analytic fold (``None`` with lookahead) and whether it flattens."""
        positions, mesh = privileged.physics.positions, privileged.physics.mesh
        handles = jnp.asarray(cloth_actions.handles(mesh))
        on_floor = floor_layer(goal, mesh)[handles]
        flat = flat_pose(goal, mesh)[handles]
        flat_action, flat_error = cloth_actions.pull(positions, handles, flat, on_floor, pickers, mesh.spacing,
                                                     coordinates)
        flatten = ~folding & (flat_error > cfg.flat_tolerance)
        fold_action = None
        if model is None:
            fold_action, fold_error = cloth_actions.pull(positions, handles, goal[handles, :2], ~on_floor, pickers,
                                                         mesh.spacing, coordinates)
            fold_action = jnp.where(fold_error <= cfg.stop_distance, cloth_actions.idle(pickers), fold_action)
        return flat_action, fold_action, flatten

    def choose(privileged, goals, folding, pickers: int, coordinates: str):
        """B cloths (leading axis B) -> float32 (B, 4 K) actions and bool (B,) folding."""
        flat_action, fold_action, flatten = jax.vmap(lambda p, g, f: one(p, g, f, pickers, coordinates))(
            privileged, goals, folding)
        if model is not None:
            mesh = privileged.physics.mesh
            tried = jax.vmap(lambda x, g: fold_proposals(x, g, mesh, pickers, coordinates, fractions))(
                privileged.physics.positions, goals)
            fold_action = cloth_actions.best_of(privileged, tried, lambda s, a: model.step(s, a)[1])  # first of equals
        return jnp.where(flatten[:, None], flat_action, fold_action), ~flatten

    def act(state, info, key, privileged):
        coordinates = cloth_actions.frame_of(privileged, "oracle_cloth_folding")
        physics = privileged.physics
        mesh = physics.mesh
        if info.goal.shape[-1] != 3 * mesh.num_particles:
            raise TypeError("oracle_cloth_folding acts on cloth folding tasks (task:side_fold, diagonal_fold or "
                            f"one_corner_inward), whose info.goal holds the folded particles; got a goal of size "
                            f"{info.goal.shape[-1]}")
        pickers = state.spec.action.shape[-1] // 4
        batch = physics.positions.shape[:-2]
        if model is not None:
            model.check_state(privileged, batch_dims=len(batch))
        flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[len(batch):]), privileged)
        goals = info.goal.reshape((-1, mesh.num_particles, 3))
        folding = state.folding.reshape(-1)
        actions, folding = choose(flat, goals, folding, pickers, coordinates)
        return actions.reshape(batch + actions.shape[-1:]), state.replace(folding=folding.reshape(batch))

    return Agent(name="oracle_cloth_folding", init=init, act=act, reset=reset, privileged=True, made_for=("cloth",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_cloth_folding", make_cloth_folding_oracle, tags=("oracle", "arena_model"))
