"""``oracle_cloth_flattening``: corner pulling with privileged particle positions and a one-action lookahead.

The analytic demonstrator of the fabric-smoothing literature (Seita et al.'s corner-pulling oracle, in the
spirit of Agent-Arena's ``oracle-towel``), for the ``cloth`` arenas' pick-and-place tools. Each action:

1. fit the flat goal: the flat cloth in the rigid pose (rotation, translation, face up or down) nearest
   the particles now in least squares (its centre kept near the origin, so it stays in view);
2. propose pulls: each of 16 edge handles (corners, edge midpoints and quarter points) placed at its goal
   position, or ``outward`` metres farther from the cloth's centre (which opens a crumpled cloth where the
   fitted goal is still a poor guess); each of an ``interior x interior`` grid of inner particles placed at
   its goal (a fold's top layer put back); each corner pinched at its tip (``tips``,
   :func:`.cloth_actions.tip_offsets`: the picker takes the corner alone, not the 2.8 cm patch around it)
   placed at its goal; and the analytic pull: among the corners and edge midpoints (``K`` pickers: the ``K``
   worst), the handle farthest from its goal to its goal, preferring particles on top (a covered one counts a
   quarter of its distance: the pickers grasp the top layer);
3. ``lookahead`` (default): run every proposal through the arena's own step (the privileged state is
   copied, not changed) and take the one that leaves the highest normalised coverage (less ``unfold_weight``
   times the mean distance from the best-fitting flat cloth, off by default); without lookahead, the
   analytic pull. Proposals other than the analytic pull move one picker (spare pickers idle);
4. once the normalised coverage reaches ``stop_coverage`` (Agent-Arena's oracle: 0.999), do nothing (pick
   and place at the workspace's empty corner).

The lookahead plans with the arena it acts in, as the planners do: config ``arena`` (the arena string; the
``jarena`` command sets it) or ``make_cloth_flattening_oracle(config, arena=...)``. It simulates 53 actions
per action taken (33 + 4 x 4 inner particles + 4 tips). On 128 crumpled 40 x 40 eval episodes the lookahead
reaches normalised coverage 0.9 within 10 actions on 93% of them (0.99, the task's success, on 78%), the analytic
pull alone on 37% (``benchmarks/RESULTS.md``). ``interior``, ``outward`` and ``tips`` were chosen on 256 train
episodes (0.9 on 96% against 94% for the earlier ``interior: 0, outward: 0.15``, which reaches 88% of the eval
episodes; ``tips``: 0.99 on 212 against 204), not on the eval ones.

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
    lookahead: bool = True  # try the proposed pulls in the arena's own dynamics and take the best
    outward: float = ranged(0.25, Range(0.0, 0.6))  # metres: a handle's second place, beyond it from the centre
    interior: int = ranged(4, Range(0, 8))  # lookahead: also a side x side grid of inner particles to their goals
    unfold_weight: float = ranged(0.0, Range(0.0, 10.0))  # lookahead: score = coverage - this x fit residual (/m)
    tips: bool = True  # lookahead: also each corner pinched at its tip (cloth_actions.tip_offsets) to its goal
    arena: str = ""  # the arena the lookahead simulates (its build string); the jarena command sets it


def centre_xy(positions: jax.Array) -> jax.Array:
    """float32 (2,): the mean particle x-y of ``positions`` (N, 3), summed in a fixed order (see :func:`flat_goal`)."""
    return fixed_sum(positions[:, :2], axis=0) / positions.shape[0]


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
    centre = centre_xy(positions)
    best, best_cost = None, None
    for mirror in (jnp.array([1.0, 1.0]), jnp.array([1.0, -1.0])):
        source = rest * mirror
        h = fixed_sum(source[:, :, None] * (now - centre)[:, None, :], axis=0)
        angle = jnp.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
        c, s = jnp.cos(angle), jnp.sin(angle)
        goal = jnp.stack([source[:, 0] * c - source[:, 1] * s, source[:, 0] * s + source[:, 1] * c], -1)
        residual = goal + centre - now
        cost = fixed_sum(dot(residual, residual), axis=0)
        if best is None:
            best, best_cost = goal, cost
        else:
            best = jnp.where(cost < best_cost, goal, best)
            best_cost = jnp.minimum(cost, best_cost)
    return best + jnp.clip(centre, -reach, reach)


def analytic_pull(positions: jax.Array, goal: jax.Array, mesh: ClothMesh, pickers: int, coordinates: str
                  ) -> jax.Array:
    """float32 (4 K,): the ``K`` corners or edge midpoints farthest from ``goal`` (N, 2) placed there (top first)."""
    handles = jnp.asarray(cloth_actions.handles(mesh))
    action, _ = cloth_actions.pull(positions, handles, goal[handles], jnp.ones(handles.shape, bool), pickers,
                                   mesh.spacing, coordinates)
    return action


def fit_residual(positions: jax.Array, mesh: ClothMesh) -> jax.Array:
    """float32 (): the mean x-y distance, metres, of the particles ``positions`` (N, 3) from the flat cloth
    best aligned with them (:func:`flat_goal` without the reach limit): 0 for a flat cloth, large for a folded one."""
    offset = flat_goal(positions, mesh, float("inf")) - positions[:, :2]
    return fixed_sum(jnp.sqrt(dot(offset, offset)), axis=0) / positions.shape[0]


def proposals(positions: jax.Array, goal: jax.Array, mesh: ClothMesh, pickers: int, coordinates: str,
              outward: float, interior: int = 0, tips: bool = False) -> jax.Array:
    """float32 (33 + interior^2 (+ 4 with tips), 4 K): the pulls the lookahead tries (the analytic pull first, then
    one picker each).

    Each of the 16 edge handles placed at its ``goal`` (N, 2) position, then each placed ``outward`` metres
    farther from the cloth's centre (its mean particle x-y) than it lies now; then each of an ``interior x
    interior`` grid of inner particles placed at its goal (a fold's top layer put back); then, with ``tips``, each
    corner pinched at its tip (:func:`.cloth_actions.tip_offsets`) and put at its goal.
    """
    handles = jnp.asarray(cloth_actions.edge_handles(mesh))
    pick = positions[handles, :2]
    away = pick - centre_xy(positions)
    away = away / (jnp.sqrt(dot(away, away))[:, None] + 1e-6)
    inner = jnp.asarray(cloth_actions.interior_handles(mesh, interior))  # (0,) for interior 0
    picks = [pick, pick, positions[inner, :2]]
    places = [goal[handles], pick + outward * away, goal[inner]]
    if tips:
        corners = jnp.asarray(cloth_actions.handles(mesh)[:4])
        offsets = cloth_actions.tip_offsets(positions, mesh)
        picks.append(positions[corners, :2] + offsets)
        places.append(goal[corners] + offsets)
    picks, places = jnp.concatenate(picks), jnp.concatenate(places)
    analytic = analytic_pull(positions, goal, mesh, pickers, coordinates)
    return jnp.concatenate([analytic[None], cloth_actions.one_picker(picks, places, pickers, coordinates)])


def make_cloth_flattening_oracle(config=None, arena=None) -> Agent:
    """The oracle for ``cloth|...,task:flattening`` arenas with pick-and-place tools.

    Args:
      config: :class:`ClothFlatteningOracleConfig` overrides.
      arena: the arena the lookahead simulates (else the one built from config ``arena``).

    Raises:
      ConfigError: with ``lookahead`` and no arena to simulate, or an arena the lookahead cannot step.
    """
    cfg = make_config(ClothFlatteningOracleConfig, config, agent="oracle_cloth_flattening")
    model = (cloth_actions.lookahead_model("oracle_cloth_flattening", cfg, arena, "the analytic corner pull alone")
             if cfg.lookahead else None)

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def score(privileged, action):
        mesh = privileged.physics.mesh
        after = model.step(privileged, action)[0].physics.positions
        value = coverage_lib.normalised_coverage(after, mesh)
        return value - cfg.unfold_weight * fit_residual(after, mesh) if cfg.unfold_weight else value

    def choose(privileged, pickers: int, coordinates: str):  # (B, ...) cloths -> float32 (B, 4 K)
        positions, mesh = privileged.physics.positions, privileged.physics.mesh
        goal = jax.vmap(lambda x: flat_goal(x, mesh, cfg.reach))(positions)
        if model is None:
            action = jax.vmap(lambda x, g: analytic_pull(x, g, mesh, pickers, coordinates))(positions, goal)
        else:
            tried = jax.vmap(lambda x, g: proposals(x, g, mesh, pickers, coordinates, cfg.outward, cfg.interior,
                                                    cfg.tips))(positions, goal)
            action = cloth_actions.best_of(privileged, tried, score)  # the analytic pull where it ties
        done = jax.vmap(lambda x: coverage_lib.normalised_coverage(x, mesh))(positions) >= cfg.stop_coverage
        return jnp.where(done[:, None], cloth_actions.idle(pickers), action)

    def act(state, info, key, privileged):
        coordinates = cloth_actions.frame_of(privileged, "oracle_cloth_flattening")
        pickers = state.spec.action.shape[-1] // 4
        batch = privileged.physics.positions.shape[:-2]
        if model is not None:
            model.check_state(privileged, batch_dims=len(batch))
        flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[len(batch):]), privileged)
        actions = choose(flat, pickers, coordinates)
        return actions.reshape(batch + actions.shape[-1:]), state

    return Agent(name="oracle_cloth_flattening", init=init, act=act, privileged=True, made_for=("cloth",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_cloth_flattening", make_cloth_flattening_oracle, tags=("oracle", "arena_model"))

