"""``pick_and_place``: Ravens' suction primitive as an action tool over the cup's control.

An action is one pick and one place in heightmap pixels, float32 (5,): ``(pick_row, pick_col, place_row,
place_col, place_yaw)``, rows and columns as :mod:`.heightmap` numbers them (fractions name points between pixel
centres) and the yaw in radians. Values outside the bounds are clipped (points to the heightmap's edge, the yaw
to [-pi, pi]: a float outside a Box's bounds is no fault); a NaN is an invalid action (the step runs the no-op, a
pick and place on the empty table's corner).

One action runs ``3 + settle`` control steps of the cup (:mod:`.physics`) in one compiled loop, Ravens'
``PickPlace``:

1. over the pick point, come down until the tip touches and turn the suction on (a movable object there is
   grasped);
2. lift ``height`` (0.32 m);
3. carry over the place point turned by ``place_yaw``, come down until the held object touches, release;
4. rise ``height`` and let the objects settle for ``settle`` control steps (Ravens steps its simulation until
   every object is still).

If nothing was grasped, step 3 only lowers the empty cup. An action's reward is the sum of its control steps'
rewards; its termination, success, goal and metrics are the task's after its last control step. A task may change
the scene once per action, before its last control step (palletizing brings the next box in).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.arenas.raven import heightmap
from jarena.arenas.raven.physics import RavenPhysics
from jarena.core.spec import Box, Spec
from jarena.core.tool import ActionTool
from jarena.core.tree import tree_where

HEIGHT = 0.32
"""Ravens' lift height above the pick and place points, metres."""


@struct.dataclass
class PickPlaceParams:
    """``height``: metres the cup rises after the pick and after the place."""

    height: jax.Array = HEIGHT


def action_spec() -> Box:
    """float32 (5,): pick row and column, place row and column (heightmap pixels), place yaw (radians)."""
    rows, cols = heightmap.ROWS - 1, heightmap.COLS - 1
    return Box(np.array([0, 0, 0, 0, -np.pi], np.float32), np.array([rows, cols, rows, cols, np.pi], np.float32))


def motion(action: jax.Array, params: PickPlaceParams, settle: int) -> jax.Array:
    """float32 (3 + settle, 6): the cup's controls for one pick-and-place ``action`` (5,) (clipped to the heightmap)."""
    spec = action_spec()
    action = jnp.clip(jnp.asarray(action, jnp.float32), jnp.asarray(spec.low, jnp.float32),
                      jnp.asarray(spec.high, jnp.float32))
    pick, place = heightmap.pixel_to_world(action[0:2]), heightmap.pixel_to_world(action[2:4])
    yaw, height = action[4], jnp.asarray(params.height, jnp.float32)
    zero, one = jnp.zeros(()), jnp.ones(())

    def control(xy, yaw, rise, suction, seek):
        return jnp.stack([xy[0], xy[1], yaw, rise, suction, seek])

    steps = [control(pick, zero, zero, one, one),  # come down on the pick point, suction on
             control(pick, zero, height, one, zero),  # lift
             control(place, yaw, zero, -one, one),  # carry over, come down until contact, release
             control(place, yaw, height, -one, zero)]  # rise
    steps += [control(place, yaw, zero, -one, zero)] * (settle - 1)
    return jnp.stack(steps)


def _on_physics(carry, after_action: Callable) -> tuple[object, jax.Array]:
    """``after_action`` applied to the one :class:`.physics.RavenPhysics` in an arena's carry (opaque to other
    tools; the Raven primitive is the innermost), and what it says of the episode's end."""
    leaves, tree = jax.tree_util.tree_flatten(carry, is_leaf=lambda x: isinstance(x, RavenPhysics))
    found = [i for i, leaf in enumerate(leaves) if isinstance(leaf, RavenPhysics)]
    if len(found) != 1:
        raise TypeError(f"pick_and_place's after_action needs the arena's RavenPhysics in its carry, found "
                        f"{len(found)}")
    leaves[found[0]], over = after_action(leaves[found[0]])
    return jax.tree_util.tree_unflatten(tree, leaves), over


def pick_and_place(settle: int = 8, after_action: Callable | None = None) -> ActionTool:
    """Ravens' pick-and-place primitive in heightmap pixels (see the module docstring); ``settle`` control steps
    after the place (the first also lifts the cup away).

    ``after_action``: ``(physics) -> (physics, over)``, a task's change to the scene between actions (a box
    coming in), applied once per action before its last control step, whose physics step then takes it in
    (kinematics, contacts); ``over`` (bool ()) ends the episode (the action's outcome is ``terminated``).
    """
    settle = int(settle)
    if settle < 1:
        raise ValueError(f"pick_and_place needs at least 1 settle step, got {settle}")

    def spec(inner: Spec):
        shape = getattr(inner, "shape", None)
        if not isinstance(inner, Box) or shape != (6,):
            raise TypeError(f"pick_and_place drives a Raven suction cup's control, a Box of shape (6,); this "
                            f"arena's control is {inner!r}")
        return action_spec()

    def no_op(inner_no_op, inner):
        return jnp.zeros((5,), jnp.float32)  # the empty table's corner (layouts keep 7 cm from the edges)

    def step(state, action, carry, inner, params, inner_spec):
        controls = motion(action, params, settle)
        if after_action is None:
            carry, outcomes = jax.lax.scan(inner, carry, controls)
            last = jax.tree_util.tree_map(lambda x: x[-1], outcomes)
            return carry, last.replace(reward=jnp.sum(outcomes.reward)), state

        # one loop body, the change selected at the last step: the physics step is compiled once
        def control_step(carry, xs):
            control, is_last = xs
            changed, over = _on_physics(carry, after_action)
            carry, outcome = inner(tree_where(is_last, changed, carry), control)
            return carry, (outcome, over & is_last)

        is_last = jnp.arange(controls.shape[0]) == controls.shape[0] - 1
        carry, (outcomes, over) = jax.lax.scan(control_step, carry, (controls, is_last))
        last = jax.tree_util.tree_map(lambda x: x[-1], outcomes)
        return carry, last.replace(reward=jnp.sum(outcomes.reward), terminated=last.terminated | over[-1]), state

    return ActionTool(step=step, spec=spec, no_op=no_op, substeps=3 + settle,
                      default_params=lambda: jax.tree_util.tree_map(jnp.float32, PickPlaceParams()),
                      name=f"pick_and_place({settle})")
