"""Action tools of the cloth: the picker's own control, and pick-and-place primitives over it.

The cloth's dynamics take one low-level control per step, float32 ``(K, 4)``: each picker's displacement
in metres and its grip (see :mod:`.physics`). The tools here turn agent actions into that control:

- ``picker(speed)``: the low-level velocity control, an action in ``[-1, 1]^(K x 4)`` scaled to at most
  ``speed`` metres per step (SoftGym's picker action).
- ``pick_and_place(K)``: one action = for each picker a pick and a place point, flat float32 ``(4 K,)`` in
  ``[-1, 1]``, ``(pick_x, pick_y, place_x, place_y)`` per picker, normalised by the workspace half-width
  (the camera's view at the floor, 0.62 m). One action runs a scripted motion of ``steps_per_action``
  physics steps in one compiled call (see :func:`motion`): from the ready pose to the pick point, grasp,
  lift to the carry height, carry, lower to the place height, release, return to the ready pose, settle.
- ``pixel_pick_and_place(K)``: the same with pick and place points in normalised image coordinates of
  the top-down camera (``u`` left to right, ``v`` top to bottom, as :mod:`.camera`), SoftGym's and
  Agent-Arena's primitive; points are projected onto the floor plane at the pick and place heights.

The primitives assume the pickers start each action at the ready pose, where every primitive (and the
initial-state procedures) leave them. The reward, success and metrics of an action are the task's at its
last physics step; the task's per-step work in earlier steps is dead code that XLA removes.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from jarena.arenas.cloth import camera as camera_lib
from jarena.arenas.cloth.physics import READY_HEIGHT
from jarena.core.spec import Box, Spec
from jarena.core.tool import ActionTool

WORKSPACE_HALF_WIDTH = 0.6213
"""Half-width of the square the normalised coordinates span, metres: SoftGym's camera (1.5 m, 45 deg) at the floor."""


@dataclasses.dataclass(frozen=True)
class Timing:
    """Physics steps of each phase of a pick-and-place (static: they size the compiled loop).

    The carry's 32 steps (0.32 s) move the picker at most ~1.5 m/s over the workspace's half-width and
    typically 0.5-1 m/s. A cloth dragged faster slides on after release (the floor's Coulomb friction,
    0.75 g, takes 0.4 s to stop a cloth moving at 3 m/s): with 16 steps the corner-pulling oracle
    flattened 14 of 24 crumpled 24 x 24 cloths to 0.9 coverage within 10 actions, with 32, 20-23. Shorter
    phases trade that for speed: on 128 crumpled 40 x 40 eval episodes the flattening oracle reaches 0.9 on 93%
    with these 68 steps (2,483 actions/s for 1024 cloths on an H200) and on 84% with ``(2, 16, 2, 8)``, 32 steps
    (5,115 actions/s; ``benchmarks/RESULTS.md``, "Cloth").
    """

    lift: int = 4
    carry: int = 32
    lower: int = 4
    settle: int = 24

    def __post_init__(self):
        for name in ("lift", "carry", "lower", "settle"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"pick-and-place phase {name!r} needs at least 1 step, got {getattr(self, name)}")

    @property
    def steps(self) -> int:
        """Physics steps per action: approach, grasp, lift, carry, lower, release, return, settle."""
        return 4 + self.lift + self.carry + self.lower + self.settle


@struct.dataclass
class PickPlaceParams:
    """Heights of the motion, metres (traced: vmap them).

    Attributes:
      pick_height: the picker closes this high above the floor (it grasps what lies within its radius).
      carry_height: height of the carry (SoftGym's pre-grasp height 0.05 m).
      place_height: the picker opens this high above the floor.
      workspace: half-width of the square spanned by normalised coordinates, metres.
    """

    pick_height: jax.Array = 0.01
    carry_height: jax.Array = 0.05
    place_height: jax.Array = 0.02
    workspace: jax.Array = WORKSPACE_HALF_WIDTH


def _check_picker_control(inner: Spec, num_pickers: int, name: str) -> None:
    shape = getattr(inner, "shape", None)
    if not isinstance(inner, Box) or shape is None or len(shape) != 2 or shape[1] != 4:
        raise TypeError(f"{name} drives a cloth's picker control, a Box of shape (K, 4); this arena's control is "
                        f"{inner!r}")
    if num_pickers is not None and shape[0] != num_pickers:
        raise ValueError(f"{name} moves {num_pickers} picker(s) but the cloth has {shape[0]}; build the cloth with "
                         f"pickers:{num_pickers} or use {name.split('(')[0]}({shape[0]})")


def motion(pick: jax.Array, place: jax.Array, params: PickPlaceParams, timing: Timing) -> jax.Array:
    """The low-level controls of one pick-and-place, float32 ``(timing.steps, K, 4)``.

    Args:
      pick: float32 (K, 2) world x-y points to pick at, metres.
      place: float32 (K, 2) world x-y points to place at, metres.
      params: heights.
      timing: phase lengths.
    """
    k = pick.shape[0]
    ready = jnp.array([0.0, 0.0, READY_HEIGHT], jnp.float32)
    zeros = jnp.zeros((k, 1), jnp.float32)

    def phase(delta, grip, n):
        grip = jnp.full((k, 1), grip, jnp.float32)
        return jnp.broadcast_to(jnp.concatenate([delta, grip], -1), (n, k, 4))

    pick3 = jnp.concatenate([pick, jnp.full((k, 1), params.pick_height)], -1)
    place3 = jnp.concatenate([place, jnp.full((k, 1), params.place_height)], -1)
    up = params.carry_height - params.pick_height
    down = params.place_height - params.carry_height
    return jnp.concatenate([
        phase(pick3 - ready, -1.0, 1),  # approach, open
        phase(jnp.zeros((k, 3)), 1.0, 1),  # grasp
        phase(jnp.concatenate([jnp.zeros((k, 2)), zeros + up / timing.lift], -1), 1.0, timing.lift),
        phase(jnp.concatenate([(place - pick) / timing.carry, zeros], -1), 1.0, timing.carry),
        phase(jnp.concatenate([jnp.zeros((k, 2)), zeros + down / timing.lower], -1), 1.0, timing.lower),
        phase(jnp.zeros((k, 3)), -1.0, 1),  # release
        phase(ready - place3, -1.0, 1),  # back to the ready pose, open
        phase(jnp.zeros((k, 3)), -1.0, timing.settle),
    ])


@struct.dataclass
class Frame:
    """The state of a pick-and-place tool: which coordinates its actions are in (static), for oracles."""

    coordinates: str = struct.field(pytree_node=False, default="world")


def coordinates_of(tool_state) -> str | None:
    """``"pixel"`` or ``"world"``: the frame of the first pick-and-place tool in an arena's tool state."""
    if isinstance(tool_state, Frame):
        return tool_state.coordinates
    if isinstance(tool_state, tuple | list):
        for s in tool_state:
            found = coordinates_of(s)
            if found is not None:
                return found
    return None


def _run(controls: jax.Array, carry, inner):
    """Runs ``controls`` (T, ...) through ``inner``; the outcome is the last step's.

    The first T - 1 steps are a scan whose outcomes XLA drops (the task's metrics, such as the coverage
    raster, run only after the last step), the last step a call after it. ``inner`` (a physics step and the
    task's update) is traced once, and both places evaluate its jaxpr: the same operations as two traces.
    """
    step, hoisted = jax.closure_convert(inner, carry, controls[0])

    def body(c, control):
        c, _ = step(c, control, *hoisted)
        return c, None

    carry, _ = jax.lax.scan(body, carry, controls[:-1])
    return step(carry, controls[-1], *hoisted)


def _pick_place_tool(num_pickers: int, timing: Timing, name: str, to_world, default_params,
                     coordinates: str) -> ActionTool:
    k = int(num_pickers)
    if k < 1:
        raise ValueError(f"{name} needs at least one picker, got {num_pickers}")

    def spec(inner):
        _check_picker_control(inner, k, name)
        return Box(-1.0, 1.0, (4 * k,), jnp.float32)

    def no_op(inner_no_op, inner):
        # pick and place at the workspace's corner, where no cloth lies: the cloth only settles
        return jnp.tile(jnp.array([-1.0, -1.0, -1.0, -1.0], jnp.float32), k)

    def step(state, action, carry, inner, params, inner_spec):
        params = jax.lax.optimization_barrier(params)  # as the physics': the same bits with params as constants
        points = jnp.clip(jnp.asarray(action, jnp.float32).reshape(k, 4), -1.0, 1.0)
        pick = to_world(points[:, :2], params.pick_height, params)
        place = to_world(points[:, 2:], params.place_height, params)
        carry, outcome = _run(motion(pick, place, params, timing), carry, inner)
        return carry, outcome, state

    return ActionTool(step=step, spec=spec, no_op=no_op, default_params=default_params, substeps=timing.steps,
                      reset=lambda key, params, inner: Frame(coordinates), name=f"{name}({k})")


def pick_and_place(num_pickers: int = 1, lift: int = 4, carry: int = 32, lower: int = 4,
                   settle: int = 24) -> ActionTool:
    """Pick-and-place in normalised world coordinates (see the module docstring); phase lengths in steps."""
    def to_world(points, height, params):
        return points * params.workspace

    return _pick_place_tool(num_pickers, Timing(lift, carry, lower, settle), "pick_and_place", to_world,
                            lambda: jax.tree_util.tree_map(jnp.float32, PickPlaceParams()), "world")


@struct.dataclass
class PixelPickPlaceParams(PickPlaceParams):
    """:class:`PickPlaceParams` and the camera whose pixels the actions name."""

    camera: camera_lib.CameraParams = dataclasses.field(default_factory=camera_lib.CameraParams)


def pixel_pick_and_place(num_pickers: int = 1, lift: int = 4, carry: int = 32, lower: int = 4,
                         settle: int = 24) -> ActionTool:
    """Pick-and-place in the top-down camera's normalised image coordinates ``(u, v)`` per point."""
    def to_world(points, height, params):
        return camera_lib.pixel_to_world(points, height, params.camera)

    return _pick_place_tool(num_pickers, Timing(lift, carry, lower, settle), "pixel_pick_and_place", to_world,
                            lambda: jax.tree_util.tree_map(jnp.float32, PixelPickPlaceParams()), "pixel")


def picker(speed: float = 0.05) -> ActionTool:
    """The pickers' velocity control: action ``[-1, 1]^(K, 4)``; displacement = action x ``speed`` metres per step.

    The grip channel passes unchanged (``> 0`` closes). SoftGym's picker moves at most 0.05 m per step.
    """
    speed = float(speed)
    if not speed > 0:
        raise ValueError(f"picker speed must be positive (metres per step), got {speed}")

    def spec(inner):
        _check_picker_control(inner, None, "picker")
        return Box(-1.0, 1.0, inner.shape, jnp.float32)

    def no_op(inner_no_op, inner):
        return jnp.concatenate([jnp.zeros(inner.shape[:1] + (3,), jnp.float32),
                                -jnp.ones(inner.shape[:1] + (1,), jnp.float32)], -1)

    def step(state, action, carry, inner, params, inner_spec):
        action = jnp.clip(jnp.asarray(action, jnp.float32), -1.0, 1.0)
        control = jnp.concatenate([action[:, :3] * params, action[:, 3:]], -1)
        carry, outcome = inner(carry, control)
        return carry, outcome, state

    return ActionTool(step=step, spec=spec, no_op=no_op, default_params=lambda: jnp.float32(speed),
                      name=f"picker({speed:g})")
