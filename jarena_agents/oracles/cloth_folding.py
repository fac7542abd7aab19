"""``oracle_cloth_folding``: the scripted fold for the ``cloth`` folding tasks, with privileged particle positions.

Agent-Arena's and SoftGym's folding oracles pick the corners of the folding side and place them where the fold
takes them. This one reads the goal the task puts in ``info.goal`` (the folded particle positions, any of
``side_fold``, ``diagonal_fold``, ``one_corner_inward``), so one oracle serves every fold. Each action:

1. the flat cloth the goal folds (:func:`flat_pose`): the rest grid mapped onto the goal's floor layer;
2. until the episode's first fold, while a handle (corner or edge midpoint, :func:`.cloth_actions.handles`)
   of the floor layer lies more than ``flat_tolerance`` from that flat pose (a crumpled start), flatten: pull
   the handle farthest from its flat position there (as ``oracle_cloth_flattening``, toward this pose);
3. then fold, and never flatten again in the episode (that would undo the fold): pick the handle of the
   folding side farthest from its goal and place it on its goal (``K`` pickers: the ``K`` worst), preferring
   handles on top (a covered one counts a quarter: the pickers grasp the top layer);
4. once every handle is within ``stop_distance`` of its goal, do nothing (pick and place at the workspace's
   empty corner).

Actions are in the frame of the arena's tool, as the flattening oracle's.
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
from jarena_agents.config import Range, make_config, ranged
from jarena_agents.oracles import cloth_actions
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class ClothFoldingOracleConfig:
    flat_tolerance: float = ranged(0.04, Range(0.0, 1.0))  # metres: floor-layer handles this far off: flatten first
    stop_distance: float = ranged(0.1, Range(0.0, 1.0))  # metres: every handle this near its goal: stop


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


def make_cloth_folding_oracle(config=None) -> Agent:
    """The oracle for ``cloth|...,task:<fold>`` arenas (``side_fold``, ``diagonal_fold``, ``one_corner_inward``)."""
    cfg = make_config(ClothFoldingOracleConfig, config, agent="oracle_cloth_folding")

    def init(key, spec, num_arenas):
        return FoldingOracleState(folding=jnp.zeros((num_arenas,), bool), spec=spec)

    def reset(state, mask):
        return state.replace(folding=state.folding & ~mask)

    def one(positions, goal, folding, mesh: ClothMesh, pickers: int, coordinates: str):
        handles = jnp.asarray(cloth_actions.handles(mesh))
        on_floor = floor_layer(goal, mesh)[handles]
        flat = flat_pose(goal, mesh)[handles]
        folded = goal[handles, :2]
        flat_action, flat_error = cloth_actions.pull(positions, handles, flat, on_floor, pickers, mesh.spacing,
                                                     coordinates)
        fold_action, fold_error = cloth_actions.pull(positions, handles, folded, ~on_floor, pickers, mesh.spacing,
                                                     coordinates)
        flatten = ~folding & (flat_error > cfg.flat_tolerance)
        action = jnp.where(flatten, flat_action, fold_action)
        done = ~flatten & (fold_error <= cfg.stop_distance)
        return jnp.where(done, cloth_actions.idle(pickers), action), ~flatten

    def act(state, info, key, privileged):
        coordinates = cloth_actions.frame_of(privileged, "oracle_cloth_folding")
        physics = privileged.physics
        mesh = physics.mesh
        if info.goal.shape[-1] != 3 * mesh.num_particles:
            raise TypeError("oracle_cloth_folding acts on cloth folding tasks (task:side_fold, diagonal_fold or "
                            f"one_corner_inward), whose info.goal holds the folded particles; got a goal of size "
                            f"{info.goal.shape[-1]}")
        pickers = state.spec.action.shape[-1] // 4
        positions = physics.positions
        batch = positions.shape[:-2]
        flat = positions.reshape((-1,) + positions.shape[-2:])
        goals = info.goal.reshape((-1, mesh.num_particles, 3))
        folding = state.folding.reshape(-1)
        actions, folding = jax.vmap(lambda p, g, f: one(p, g, f, mesh, pickers, coordinates))(flat, goals, folding)
        return actions.reshape(batch + actions.shape[-1:]), state.replace(folding=folding.reshape(batch))

    return Agent(name="oracle_cloth_folding", init=init, act=act, reset=reset, privileged=True, made_for=("cloth",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_cloth_folding", make_cloth_folding_oracle, tags=("oracle",))
