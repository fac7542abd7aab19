"""``oracle_cloth_flattening``: corner pulling with privileged particle positions.

The analytic demonstrator of the fabric-smoothing literature (Seita et al.'s corner-pulling oracle, in the
spirit of Agent-Arena's ``oracle-towel``), for the ``cloth`` arenas' pick-and-place tools. Each action:

1. fit the flat goal: the flat cloth in the rigid pose (rotation, translation, face up or down) nearest
   the particles now in least squares (its centre kept near the origin, so it stays in view);
2. among the corners and edge midpoints (``K`` pickers: the ``K`` worst), pick the particle farthest from
   its goal position and place it there, preferring particles on top (a covered one counts a quarter of its
   distance: the pickers grasp the top layer);
3. once the normalised coverage reaches ``stop_coverage`` (Agent-Arena's oracle: 0.999), do nothing (pick
   and place at the workspace's empty corner).

Actions are in the frame of the arena's tool (pixels of the top-down camera or normalised world points),
read from the tool's state; the default heights and camera of :mod:`jarena.arenas.cloth.tools` are assumed.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jarena.arenas.cloth import coverage as coverage_lib
from jarena.arenas.cloth.collision import dot, fixed_sum
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import Range, in_unit_interval, make_config, ranged
from jarena_agents.oracles import cloth_actions
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class ClothFlatteningOracleConfig:
    reach: float = ranged(0.15, Range(0.0, 0.6))  # metres: the goal's centre stays this close to the origin
    stop_coverage: float = in_unit_interval(0.999)  # normalised coverage at which the oracle stops


def flat_goal(positions: jax.Array, mesh: ClothMesh, reach: float) -> jax.Array:
    """float32 (N, 2): the flat cloth best aligned with ``positions`` (N, 3) from above.

    The rigid motion in the plane (rotation and translation, face up or mirrored face down) that brings
    the rest grid nearest the particles in least squares (2-D Kabsch), with its centre kept within
    ``reach`` metres of the origin on each axis so that the goal stays in view.
    """
    # every sum in a fixed order (collision.fixed_sum, not jnp.sum or a matmul, whose order can change with
    # the batch size): the oracle acts the same, to the bit, in any batch
    rest = jnp.asarray(mesh.rest_positions[:, :2])  # centred at the origin
    now = positions[:, :2]
    centre = fixed_sum(now, axis=0) / now.shape[0]
    best, best_cost = None, None
    for mirror in (jnp.array([1.0, 1.0]), jnp.array([1.0, -1.0])):
        source = rest * mirror
        h = fixed_sum(source[:, :, None] * (now - centre)[:, None, :], axis=0)
        angle = jnp.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
        c, s = jnp.cos(angle), jnp.sin(angle)
        goal = jnp.stack([source[:, 0] * c - source[:, 1] * s, source[:, 0] * s + source[:, 1] * c], -1)
        cost = fixed_sum(dot(goal + centre - now, goal + centre - now), axis=0)
        if best is None:
            best, best_cost = goal, cost
        else:
            best = jnp.where(cost < best_cost, goal, best)
            best_cost = jnp.minimum(cost, best_cost)
    return best + jnp.clip(centre, -reach, reach)


def make_cloth_flattening_oracle(config=None) -> Agent:
    """The oracle for ``cloth|...,task:flattening`` arenas with pick-and-place tools."""
    cfg = make_config(ClothFlatteningOracleConfig, config, agent="oracle_cloth_flattening")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def one(positions, mesh: ClothMesh, pickers: int, coordinates: str):
        goal = flat_goal(positions, mesh, cfg.reach)
        handles = jnp.asarray(cloth_actions.handles(mesh))
        action, _ = cloth_actions.pull(positions, handles, goal[handles], jnp.ones(handles.shape, bool), pickers,
                                       mesh.spacing, coordinates)
        done = coverage_lib.normalised_coverage(positions, mesh) >= cfg.stop_coverage
        return jnp.where(done, cloth_actions.idle(pickers), action)

    def act(state, info, key, privileged):
        coordinates = cloth_actions.frame_of(privileged, "oracle_cloth_flattening")
        physics = privileged.physics
        mesh = physics.mesh
        pickers = state.spec.action.shape[-1] // 4
        positions = physics.positions
        batch = positions.shape[:-2]
        flat = positions.reshape((-1,) + positions.shape[-2:])
        actions = jax.vmap(lambda p: one(p, mesh, pickers, coordinates))(flat)
        return actions.reshape(batch + actions.shape[-1:]), state

    return Agent(name="oracle_cloth_flattening", init=init, act=act, privileged=True, made_for=("cloth",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_cloth_flattening", make_cloth_flattening_oracle, tags=("oracle",))

