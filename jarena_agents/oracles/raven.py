"""``oracle_raven``: Ravens' scripted demonstrator for the ``raven`` tabletop arenas (``Task._discrete_oracle``).

Each action, from the privileged state (object poses, the goal's current stage, the true heightmap's object mask):

1. objects that already match a target they may go to are set aside with that target (matching without
   replacement, in object order, as Ravens does);
2. of the others, the one farthest from its nearest allowed target is picked (only objects seen from above);
3. the pick point is a pixel drawn uniformly from that object's mask in the heightmap;
4. the place point is where the pick point goes when the object is moved onto that target: the target's pose
   composed with the pick point's offset in the object's frame, turned by the target's heading less the
   object's (the cup picks with heading 0).

A goal scored by a zone (palletizing) keeps Ravens' targets for its objects, each box's place in the stack, so the
oracle puts each box that comes in at its place. With nothing left to place it does nothing (the no-op: a pick and
place on the empty table's corner). Its randomness (the pick pixel) comes from the key and the episode id, so an
episode gets the same actions in any batch.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from jarena.arenas.raven import heightmap, poses
from jarena.arenas.raven.scoring import Goal, current_goal, goal_state, heading_error, planar_poses
from jarena.core.agent import Agent
from jarena_agents.basic import SpecState
from jarena_agents.config import make_config
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class RavenOracleConfig:
    pass


def unmatched(planar: jax.Array, goal: Goal, pos_eps: jax.Array, rot_eps: jax.Array) -> jax.Array:
    """bool (O, T): the allowed object-target pairs left once objects that match a target are set aside with it
    (Ravens' order: objects in turn, each taking the first target it matches)."""
    allowed = goal.matches & goal.present[:, None] & goal.target_present[None, :]
    mine = planar[goal.objects]
    distance = jnp.linalg.norm(mine[:, None, :2] - goal.targets[None, :, :2], axis=-1)
    heading = heading_error(mine[:, None, 3], goal.targets[None, :, 3], goal.symmetry[:, None])
    hits = (distance < pos_eps) & (heading < rot_eps)
    targets = allowed.shape[1]

    def set_aside(k, left):  # pair k: object k // targets, target k % targets, in Ravens' order
        i, j = k // targets, k % targets
        take = left[i, j] & hits[i, j]
        return jnp.where(take, left.at[i, :].set(False).at[:, j].set(False), left)

    return jax.lax.fori_loop(0, allowed.size, set_aside, allowed)


def choose(planar: jax.Array, goal: Goal, objects_seen: jax.Array, pos_eps: jax.Array, rot_eps: jax.Array,
           key: jax.Array) -> jax.Array:
    """One arena's action, float32 (5,) (:mod:`jarena.arenas.raven.primitive`).

    Args:
      planar: float32 (N, 4) every object's ``(x, y, z, yaw)``; goal: the episode's goal;
      objects_seen: int32 (ROWS, COLS) the heightmap's object per pixel; pos_eps, rot_eps: the task's tolerances.
    """
    left = unmatched(planar, goal, pos_eps, rot_eps)
    mine = planar[goal.objects]
    distance = jnp.linalg.norm(mine[:, None, :3] - goal.targets[None, :, :3], axis=-1)
    distance = jnp.where(left, distance, jnp.inf)
    nearest = jnp.argmin(distance, axis=-1)
    farthest = jnp.where(jnp.any(left, axis=-1), jnp.min(distance, axis=-1), 0.0)
    seen = jax.vmap(lambda o: jnp.any(objects_seen == o))(goal.objects)
    wanted = seen & (farthest > 0)
    pick = jnp.argmax(jnp.where(wanted, farthest, -1.0))
    mask = (objects_seen == goal.objects[pick]).reshape(-1)
    index = jax.random.categorical(key, jnp.where(mask, 0.0, -jnp.inf))
    pick_rc = jnp.stack([index // heightmap.COLS, index % heightmap.COLS]).astype(jnp.float32)
    pick_xy = heightmap.pixel_to_world(pick_rc)
    obj, target = mine[pick], goal.targets[nearest[pick]]
    offset = poses.rotate(poses.yaw_quat(-obj[3]), jnp.concatenate([pick_xy - obj[:2], jnp.zeros(1)]))
    place_xy = target[:2] + poses.rotate(poses.yaw_quat(target[3]), offset)[:2]
    action = jnp.concatenate([pick_rc, heightmap.world_to_pixel(place_xy),
                              poses.wrap_angle(target[3] - obj[3])[None]])
    return jnp.where(jnp.any(wanted), action, jnp.zeros(5, jnp.float32))


def make_raven_oracle(config=None) -> Agent:
    """The oracle for ``raven|task:...`` arenas (module docstring)."""
    cfg = make_config(RavenOracleConfig, config, agent="oracle_raven")

    def init(key, spec, num_arenas):
        return SpecState(spec)

    def act(state, info, key, privileged):
        physics, scoring = privileged.physics, goal_state(privileged.task)
        if scoring is None:
            raise TypeError("oracle_raven reads the goal of a raven arena's pose scoring, which this arena's task "
                            "does not have")
        scene = physics.scene
        batch = info.episode.shape
        count = math.prod(batch)

        def one(phys, goal, stage, pos_eps, rot_eps, episode):
            view = heightmap.render(scene, phys.data.geom_xpos, phys.data.geom_xmat, phys.geom_size, phys.geom_rgb)
            return choose(planar_poses(phys), current_goal(goal, stage), view.object, pos_eps, rot_eps,
                          jax.random.fold_in(key, episode))

        flat = jax.tree_util.tree_map(lambda x: x.reshape((count,) + x.shape[len(batch):]),
                                      (physics, scoring.goal, scoring.stage, scoring.pos_eps, scoring.rot_eps,
                                       info.episode))
        actions = jax.vmap(one)(*flat)
        return actions.reshape(batch + (5,)), state

    return Agent(name="oracle_raven", init=init, act=act, privileged=True, made_for=("raven",),
                 config=dataclasses.asdict(cfg))


register_agent("oracle_raven", make_raven_oracle, tags=("oracle",))
